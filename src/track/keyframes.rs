//! User keyframes (method.md §5, paper §4.3).
//!
//! Where silhouettes are ambiguous (occlusion), the user supplies a keyframe: a
//! frame index, a subset of the 30 motion parameters and an impact range. For a
//! frame inside the range, the search starts from the interpolation between the
//! keyframe and the pose predicted from the previous frames, instead of that
//! prediction alone.
//!
//! The file format (docs/contracts.md, "Keyframes"):
//!
//! ```json
//! { "keyframes": [ { "frame": 42, "range": 10, "params": { "l_shoulder_x": 35.0, "l_elbow": 80.0 } } ] }
//! ```
//!
//! Angles in degrees, translations in cm; names as in [`MOTION`]. Unknown fields
//! are ignored (forward compatibility); `keyframes` and each keyframe's `frame`,
//! `range` and `params` are required.

use std::fmt;

use serde::de::{self, IgnoredAny, MapAccess, SeqAccess, Visitor};
use serde::ser::{SerializeMap, SerializeStruct};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::body::params::{motion_index, Pose, MOTION, MOTION_COUNT};

/// Most keyframes one list may hold.
pub const MAX_KEYFRAMES: usize = 10_000;
/// Largest keyframes text accepted by [`Keyframes::parse`] (1 MiB).
pub const MAX_BYTES: usize = 1 << 20;

/// A small valid example, quoted in error messages.
const EXAMPLE: &str = r#"{"keyframes": [{"frame": 42, "range": 10, "params": {"l_elbow": 80.0}}]}"#;
const EXAMPLE_KEYFRAME: &str = r#"{"frame": 42, "range": 10, "params": {"l_elbow": 80.0}}"#;

/// One user keyframe.
#[derive(Clone, Debug, PartialEq)]
pub struct Keyframe {
    /// Frame index in the clip (0-based).
    pub frame: usize,
    /// Impact range in frames: the keyframe affects frames `frame - range ..= frame + range`.
    pub range: usize,
    /// (parameter index into [`MOTION`], value in the parameter's unit), sorted by
    /// index, no duplicates.
    pub params: Vec<(usize, f64)>,
}

/// Why a keyframe list was rejected. Every message is one line that names the
/// keyframe (`keyframes[i]`, its position in the list as given, and its frame when
/// known) and the problem.
#[derive(Debug, thiserror::Error)]
pub enum KeyframeError {
    #[error("keyframes text is {bytes} bytes, more than the limit of {limit} bytes (1 MiB)")]
    TooLarge { bytes: usize, limit: usize },

    #[error("invalid keyframes JSON at line {line} column {column}: {message}")]
    Json {
        line: usize,
        column: usize,
        message: String,
    },

    #[error("keyframes JSON has no \"keyframes\" list; expected e.g. {}", EXAMPLE)]
    MissingList,

    #[error("{count} keyframes, more than the limit of {limit}")]
    TooMany { count: usize, limit: usize },

    #[error(
        "keyframes[{index}] must be an object, got {got}; expected e.g. {}",
        EXAMPLE_KEYFRAME
    )]
    NotAnObject { index: usize, got: String },

    #[error("{}: missing \"{field}\"", at(*.index, *.frame))]
    MissingField {
        index: usize,
        frame: Option<usize>,
        field: &'static str,
    },

    #[error(
        "{}: \"{field}\" must be a whole number from 0 to {}, got {got}",
        at(*.index, *.frame),
        usize::MAX
    )]
    NotAWholeNumber {
        index: usize,
        frame: Option<usize>,
        field: &'static str,
        got: String,
    },

    #[error(
        "keyframes[{index}] (frame {frame}): \"params\" must be an object of parameter names to values, got {got}"
    )]
    ParamsNotAnObject {
        index: usize,
        frame: usize,
        got: String,
    },

    #[error("keyframes[{index}] (frame {frame}): \"params\" is empty; set at least one parameter")]
    EmptyParams { index: usize, frame: usize },

    #[error("keyframes[{index}] (frame {frame}): unknown parameter \"{name}\"{}", hint(*.suggestion))]
    UnknownParameter {
        index: usize,
        frame: usize,
        name: String,
        suggestion: Option<&'static str>,
    },

    #[error(
        "keyframes[{index}] (frame {frame}): parameter index {param} is out of range 0..{}",
        MOTION_COUNT
    )]
    ParameterIndex {
        index: usize,
        frame: usize,
        param: usize,
    },

    #[error("keyframes[{index}] (frame {frame}): parameter \"{name}\" is set twice")]
    DuplicateParameter {
        index: usize,
        frame: usize,
        name: &'static str,
    },

    #[error("keyframes[{index}] (frame {frame}): {name} must be a number, got {got}")]
    NotANumber {
        index: usize,
        frame: usize,
        name: &'static str,
        got: String,
    },

    #[error("keyframes[{index}] (frame {frame}): {name} = {value} is not a finite number")]
    NotFinite {
        index: usize,
        frame: usize,
        name: &'static str,
        value: f64,
    },

    #[error(
        "keyframes[{index}] (frame {frame}): {name} = {value} {unit} is outside its limits {lo}..{hi} {unit}"
    )]
    OutOfLimits {
        index: usize,
        frame: usize,
        name: &'static str,
        value: f64,
        lo: f64,
        hi: f64,
        unit: &'static str,
    },

    #[error(
        "keyframes[{index}] (frame {frame}) is outside the clip, which has {frame_count} frames numbered from 0"
    )]
    OutsideClip {
        index: usize,
        frame: usize,
        frame_count: usize,
    },

    #[error(
        "keyframes[{first}] and keyframes[{second}] are both on frame {frame}; merge them into one keyframe"
    )]
    DuplicateFrame {
        first: usize,
        second: usize,
        frame: usize,
    },
}

/// "keyframes[i] (frame f)" or "keyframes[i]" when the frame is not known yet.
fn at(index: usize, frame: Option<usize>) -> String {
    match frame {
        Some(f) => format!("keyframes[{index}] (frame {f})"),
        None => format!("keyframes[{index}]"),
    }
}

/// The tail of an unknown-parameter message: a suggestion and the valid names.
fn hint(suggestion: Option<&'static str>) -> String {
    let names: Vec<&str> = MOTION.iter().map(|m| m.name).collect();
    let list = format!(
        "valid names (as in the motion JSON's \"parameters\"): {}",
        names.join(", ")
    );
    match suggestion {
        Some(s) => format!("; did you mean \"{s}\"? {list}"),
        None => format!("; {list}"),
    }
}

/// The closest parameter name to a misspelt one, if it is close enough.
fn suggest(name: &str) -> Option<&'static str> {
    let lower = name.to_ascii_lowercase();
    MOTION
        .iter()
        .map(|m| (edit_distance(&lower, m.name), m.name))
        .filter(|&(d, _)| d <= 2)
        .min_by_key(|&(d, _)| d)
        .map(|(_, n)| n)
}

/// Levenshtein distance over chars (names are short; cost is irrelevant).
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let up = row[j + 1];
            row[j + 1] = (up + 1).min(row[j] + 1).min(diag + usize::from(ca != cb));
            diag = up;
        }
    }
    row[b.len()]
}

/// A short description of a JSON value for messages: numbers as written, other
/// kinds by name (strings can be long and contain anything).
fn describe(v: &serde_json::Value) -> String {
    use serde_json::Value;
    match v {
        Value::Null => "null".into(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => n.to_string(),
        Value::String(_) => "a string".into(),
        Value::Array(_) => "an array".into(),
        Value::Object(_) => "an object".into(),
    }
}

/// A non-negative integer that fits a `usize`, or `None`.
fn whole(v: &serde_json::Value) -> Option<usize> {
    v.as_u64().and_then(|n| usize::try_from(n).ok())
}

/// A validated keyframe list, sorted by frame, at most one keyframe per frame.
#[derive(Clone, Debug, Default)]
pub struct Keyframes {
    /// Sorted by frame.
    list: Vec<Keyframe>,
    /// Position of each keyframe in the list as given (for error messages).
    positions: Vec<usize>,
    /// Largest impact range, to bound the search in [`Keyframes::start_pose`].
    max_range: usize,
}

/// Equality is that of the keyframes; where they stood in the input does not matter.
impl PartialEq for Keyframes {
    fn eq(&self, other: &Self) -> bool {
        self.list == other.list
    }
}

impl Keyframes {
    /// Parses and validates the contract JSON.
    pub fn parse(text: &str) -> Result<Keyframes, KeyframeError> {
        if text.len() > MAX_BYTES {
            return Err(KeyframeError::TooLarge {
                bytes: text.len(),
                limit: MAX_BYTES,
            });
        }
        let raw: RawFile = serde_json::from_str(text).map_err(json_error)?;
        let entries = raw.keyframes.ok_or(KeyframeError::MissingList)?;
        if entries.len() > MAX_KEYFRAMES {
            return Err(KeyframeError::TooMany {
                count: entries.len(),
                limit: MAX_KEYFRAMES,
            });
        }
        let mut list = Vec::with_capacity(entries.len());
        for (index, entry) in entries.into_iter().enumerate() {
            let mut kf = convert(index, entry)?;
            validate_one(index, &mut kf)?;
            list.push(kf);
        }
        finish(list)
    }

    /// The keyframes counted from clip frame `first` (for tracking a range of the
    /// clip that starts there): an error names a keyframe before it.
    pub fn shifted(&self, first: usize) -> Result<Keyframes, String> {
        let mut list = self.list.clone();
        for kf in &mut list {
            kf.frame = kf.frame.checked_sub(first).ok_or_else(|| {
                format!(
                    "keyframe at frame {} lies before the first tracked frame {first}",
                    kf.frame
                )
            })?;
        }
        Keyframes::from_list(list).map_err(|e| e.to_string())
    }

    /// Validates a list built in code: the same checks as [`Keyframes::parse`] minus
    /// the JSON ones. Each keyframe's parameters are sorted by index.
    pub fn from_list(mut list: Vec<Keyframe>) -> Result<Keyframes, KeyframeError> {
        if list.len() > MAX_KEYFRAMES {
            return Err(KeyframeError::TooMany {
                count: list.len(),
                limit: MAX_KEYFRAMES,
            });
        }
        for (index, kf) in list.iter_mut().enumerate() {
            validate_one(index, kf)?;
        }
        finish(list)
    }

    /// The keyframes, sorted by frame.
    pub fn list(&self) -> &[Keyframe] {
        &self.list
    }

    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// Checks every keyframe lies inside a clip of `frame_count` frames.
    pub fn check_frames(&self, frame_count: usize) -> Result<(), KeyframeError> {
        // Sorted by frame: the first offender is the lowest such frame.
        match self.list.iter().position(|k| k.frame >= frame_count) {
            Some(i) => Err(KeyframeError::OutsideClip {
                index: self.positions[i],
                frame: self.list[i].frame,
                frame_count,
            }),
            None => Ok(()),
        }
    }

    /// The keyframe exactly at `frame`, if any.
    pub fn at(&self, frame: usize) -> Option<&Keyframe> {
        self.list
            .binary_search_by_key(&frame, |k| k.frame)
            .ok()
            .map(|i| &self.list[i])
    }

    /// Start pose of the search at `frame` given the pose `previous` predicted from
    /// earlier frames: for each keyframe whose impact range contains `frame`
    /// (|frame − k.frame| ≤ k.range), its parameters are interpolated towards the
    /// keyframe's values with weight t = 1 − |frame − k.frame| / (k.range + 1)
    /// (t = 1 on the keyframe itself); when several keyframes cover the frame, the
    /// nearest one (ties: the later) wins for a parameter both set. Parameters no
    /// keyframe sets keep `previous`. Returns whether any keyframe applied.
    pub fn start_pose(&self, frame: usize, previous: &Pose) -> (Pose, bool) {
        let mut pose = *previous;
        // Only keyframes within `max_range` of `frame` can cover it.
        let lo = frame.saturating_sub(self.max_range);
        let hi = frame.saturating_add(self.max_range);
        let start = self.list.partition_point(|k| k.frame < lo);
        // Per parameter: (distance, keyframe's frame, weight, value) of the winner.
        let mut best: [Option<(usize, usize, f64, f64)>; MOTION_COUNT] = [None; MOTION_COUNT];
        let mut applied = false;
        for k in self.list[start..].iter().take_while(|k| k.frame <= hi) {
            let d = frame.abs_diff(k.frame);
            if d > k.range {
                continue;
            }
            applied = true;
            // 1 − d/(range + 1), written so that huge ranges keep their precision.
            let t = ((k.range - d) as f64 + 1.0) / (k.range as f64 + 1.0);
            for &(i, v) in &k.params {
                let wins = match best[i] {
                    None => true,
                    Some((bd, bf, _, _)) => d < bd || (d == bd && k.frame > bf),
                };
                if wins {
                    best[i] = Some((d, k.frame, t, v));
                }
            }
        }
        for (i, b) in best.iter().enumerate() {
            if let Some((_, _, t, v)) = *b {
                pose[i] = if t >= 1.0 {
                    v
                } else {
                    (1.0 - t) * previous[i] + t * v
                };
            }
        }
        (pose, applied)
    }

    /// Serialises back to the contract JSON (round trip: `parse(to_json())` gives
    /// an equal list). Parameters appear in the order of [`MOTION`].
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(&JsonFile(&self.list))
            .expect("keyframes hold only finite numbers and string keys")
    }
}

/// Per-keyframe checks shared by `parse` and `from_list`; sorts the parameters.
fn validate_one(index: usize, kf: &mut Keyframe) -> Result<(), KeyframeError> {
    let frame = kf.frame;
    if kf.params.is_empty() {
        return Err(KeyframeError::EmptyParams { index, frame });
    }
    for &(param, value) in &kf.params {
        let Some(m) = MOTION.get(param) else {
            return Err(KeyframeError::ParameterIndex {
                index,
                frame,
                param,
            });
        };
        if !value.is_finite() {
            return Err(KeyframeError::NotFinite {
                index,
                frame,
                name: m.name,
                value,
            });
        }
        if value < m.lo || value > m.hi {
            return Err(KeyframeError::OutOfLimits {
                index,
                frame,
                name: m.name,
                value,
                lo: m.lo,
                hi: m.hi,
                unit: m.unit.name(),
            });
        }
    }
    kf.params.sort_by_key(|&(i, _)| i);
    if let Some(w) = kf.params.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(KeyframeError::DuplicateParameter {
            index,
            frame,
            name: MOTION[w[0].0].name,
        });
    }
    Ok(())
}

/// Sorts validated keyframes by frame and rejects two on one frame.
fn finish(list: Vec<Keyframe>) -> Result<Keyframes, KeyframeError> {
    let mut order: Vec<(usize, Keyframe)> = list.into_iter().enumerate().collect();
    order.sort_by_key(|(pos, k)| (k.frame, *pos));
    if let Some(w) = order.windows(2).find(|w| w[0].1.frame == w[1].1.frame) {
        return Err(KeyframeError::DuplicateFrame {
            first: w[0].0,
            second: w[1].0,
            frame: w[0].1.frame,
        });
    }
    let max_range = order.iter().map(|(_, k)| k.range).max().unwrap_or(0);
    let (positions, list) = order.into_iter().unzip();
    Ok(Keyframes {
        list,
        positions,
        max_range,
    })
}

/// serde_json's error as ours, its location split from its message.
fn json_error(e: serde_json::Error) -> KeyframeError {
    let (line, column) = (e.line(), e.column());
    let full = e.to_string();
    let suffix = format!(" at line {line} column {column}");
    let message = full.strip_suffix(&suffix).unwrap_or(&full).to_string();
    KeyframeError::Json {
        line,
        column,
        message,
    }
}

/// One list entry as read, before validation.
fn convert(index: usize, entry: ObjectOr<RawKeyframe>) -> Result<Keyframe, KeyframeError> {
    let raw = match entry {
        ObjectOr::Object(raw) => raw,
        ObjectOr::Other(got) => return Err(KeyframeError::NotAnObject { index, got }),
    };
    let frame_value = raw.frame.ok_or(KeyframeError::MissingField {
        index,
        frame: None,
        field: "frame",
    })?;
    let frame = whole(&frame_value).ok_or_else(|| KeyframeError::NotAWholeNumber {
        index,
        frame: None,
        field: "frame",
        got: describe(&frame_value),
    })?;
    let range_value = raw.range.ok_or(KeyframeError::MissingField {
        index,
        frame: Some(frame),
        field: "range",
    })?;
    let range = whole(&range_value).ok_or_else(|| KeyframeError::NotAWholeNumber {
        index,
        frame: Some(frame),
        field: "range",
        got: describe(&range_value),
    })?;
    let entries = match raw.params {
        None => {
            return Err(KeyframeError::MissingField {
                index,
                frame: Some(frame),
                field: "params",
            })
        }
        Some(ObjectOr::Other(got)) => {
            return Err(KeyframeError::ParamsNotAnObject { index, frame, got })
        }
        Some(ObjectOr::Object(RawParams(entries))) => entries,
    };
    let mut params = Vec::with_capacity(entries.len());
    for (name, value) in entries {
        let Some(i) = motion_index(&name) else {
            let suggestion = suggest(&name);
            return Err(KeyframeError::UnknownParameter {
                index,
                frame,
                name,
                suggestion,
            });
        };
        let Some(v) = value.as_f64().filter(|_| value.is_number()) else {
            return Err(KeyframeError::NotANumber {
                index,
                frame,
                name: MOTION[i].name,
                got: describe(&value),
            });
        };
        params.push((i, v));
    }
    Ok(Keyframe {
        frame,
        range,
        params,
    })
}

// ---------------------------------------------------------------------------
// Reading: lenient shapes so that type errors can name the keyframe.

#[derive(Deserialize)]
#[serde(expecting = "an object with a \"keyframes\" list")]
struct RawFile {
    #[serde(default)]
    keyframes: Option<Vec<ObjectOr<RawKeyframe>>>,
}

/// A keyframe object's known fields, each kept raw for validation.
struct RawKeyframe {
    frame: Option<serde_json::Value>,
    range: Option<serde_json::Value>,
    params: Option<ObjectOr<RawParams>>,
}

/// A `params` object in document order, duplicates kept (so they can be reported).
struct RawParams(Vec<(String, serde_json::Value)>);

/// Built from a JSON object's entries.
trait FromMap: Sized {
    fn from_map<'de, A: MapAccess<'de>>(map: A) -> Result<Self, A::Error>;
}

impl FromMap for RawKeyframe {
    fn from_map<'de, A: MapAccess<'de>>(mut map: A) -> Result<Self, A::Error> {
        let mut out = RawKeyframe {
            frame: None,
            range: None,
            params: None,
        };
        while let Some(key) = map.next_key::<String>()? {
            match key.as_str() {
                "frame" => set_once(&mut out.frame, "frame", map.next_value()?)?,
                "range" => set_once(&mut out.range, "range", map.next_value()?)?,
                "params" => set_once(&mut out.params, "params", map.next_value()?)?,
                _ => {
                    map.next_value::<IgnoredAny>()?;
                }
            }
        }
        Ok(out)
    }
}

/// Stores a field's value, rejecting a second occurrence (JSON null counts as absent).
fn set_once<T, E: de::Error>(slot: &mut Option<T>, name: &str, value: Option<T>) -> Result<(), E> {
    if slot.is_some() && value.is_some() {
        return Err(E::custom(format!("duplicate field `{name}` in a keyframe")));
    }
    if value.is_some() {
        *slot = value;
    }
    Ok(())
}

impl FromMap for RawParams {
    fn from_map<'de, A: MapAccess<'de>>(mut map: A) -> Result<Self, A::Error> {
        let mut entries = Vec::new();
        while let Some((k, v)) = map.next_entry::<String, serde_json::Value>()? {
            entries.push((k, v));
        }
        Ok(RawParams(entries))
    }
}

/// A JSON object read as `T`, or a description of whatever else stood there.
enum ObjectOr<T> {
    Object(T),
    Other(String),
}

impl<'de, T: FromMap> Deserialize<'de> for ObjectOr<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(ObjectOrVisitor(std::marker::PhantomData))
    }
}

struct ObjectOrVisitor<T>(std::marker::PhantomData<T>);

impl<'de, T: FromMap> Visitor<'de> for ObjectOrVisitor<T> {
    type Value = ObjectOr<T>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a JSON value")
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
        T::from_map(map).map(ObjectOr::Object)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        while seq.next_element::<IgnoredAny>()?.is_some() {}
        Ok(ObjectOr::Other("an array".into()))
    }

    fn visit_bool<E: de::Error>(self, v: bool) -> Result<Self::Value, E> {
        Ok(ObjectOr::Other(v.to_string()))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
        Ok(ObjectOr::Other(v.to_string()))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
        Ok(ObjectOr::Other(v.to_string()))
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
        Ok(ObjectOr::Other(
            serde_json::Number::from_f64(v).map_or_else(|| v.to_string(), |n| n.to_string()),
        ))
    }

    fn visit_str<E: de::Error>(self, _: &str) -> Result<Self::Value, E> {
        Ok(ObjectOr::Other("a string".into()))
    }

    fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
        Ok(ObjectOr::Other("null".into()))
    }
}

// ---------------------------------------------------------------------------
// Writing.

struct JsonFile<'a>(&'a [Keyframe]);
struct JsonKeyframe<'a>(&'a Keyframe);
struct JsonParams<'a>(&'a [(usize, f64)]);

impl Serialize for JsonFile<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let list: Vec<JsonKeyframe> = self.0.iter().map(JsonKeyframe).collect();
        let mut st = s.serialize_struct("Keyframes", 1)?;
        st.serialize_field("keyframes", &list)?;
        st.end()
    }
}

impl Serialize for JsonKeyframe<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("Keyframe", 3)?;
        st.serialize_field("frame", &self.0.frame)?;
        st.serialize_field("range", &self.0.range)?;
        st.serialize_field("params", &JsonParams(&self.0.params))?;
        st.end()
    }
}

impl Serialize for JsonParams<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for &(i, v) in self.0 {
            m.serialize_entry(MOTION[i].name, &v)?;
        }
        m.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::params::ix;

    const CONTRACT: &str = r#"{ "keyframes": [ { "frame": 42, "range": 10, "params": { "l_shoulder_x": 35.0, "l_elbow": 80.0 } } ] }"#;

    fn kf(frame: usize, range: usize, params: &[(usize, f64)]) -> Keyframe {
        Keyframe {
            frame,
            range,
            params: params.to_vec(),
        }
    }

    fn err(text: &str) -> KeyframeError {
        match Keyframes::parse(text) {
            Ok(k) => panic!("expected an error for {text}, got {k:?}"),
            Err(e) => e,
        }
    }

    fn one(frame: &str, range: &str, params: &str) -> String {
        format!(r#"{{"keyframes": [{{"frame": {frame}, "range": {range}, "params": {params}}}]}}"#)
    }

    fn assert_one_line(e: &KeyframeError) {
        let m = e.to_string();
        assert!(!m.contains('\n'), "multi-line message: {m}");
        assert!(!m.is_empty());
    }

    #[test]
    fn contract_example_parses() {
        let k = Keyframes::parse(CONTRACT).unwrap();
        assert_eq!(
            k.list(),
            &[kf(42, 10, &[(ix::L_SHOULDER, 35.0), (ix::L_ELBOW, 80.0)])]
        );
        assert!(!k.is_empty());
        assert!(k.at(42).is_some());
        assert!(k.at(41).is_none());
        assert!(k.check_frames(43).is_ok());
    }

    #[test]
    fn empty_list_is_fine_and_unknown_fields_are_ignored() {
        let k = Keyframes::parse(r#"{"keyframes": []}"#).unwrap();
        assert!(k.is_empty());
        assert_eq!(k, Keyframes::default());
        let text = r#"{"format": "x/2", "keyframes": [{"frame": 3, "range": 0, "note": {"a": [1, 2]},
            "params": {"r_knee": 10}, "weight": 0.5}], "extra": null}"#;
        let k = Keyframes::parse(text).unwrap();
        assert_eq!(k.list(), &[kf(3, 0, &[(ix::R_KNEE, 10.0)])]);
    }

    #[test]
    fn round_trip() {
        let k = Keyframes::from_list(vec![
            kf(
                90,
                3,
                &[(ix::ROOT_TX, -12.345678901234), (ix::R_ANKLE, 1e-7)],
            ),
            kf(5, 0, &[(ix::L_ELBOW, 80.0), (ix::ROOT_RY, -720.0)]),
            kf(40, 1000, &[(ix::NECK, 0.1 + 0.2)]),
        ])
        .unwrap();
        let text = k.to_json();
        let back = Keyframes::parse(&text).unwrap();
        assert_eq!(back, k);
        assert_eq!(back.to_json(), text);
        // Sorted by frame, parameters by index.
        let frames: Vec<usize> = k.list().iter().map(|k| k.frame).collect();
        assert_eq!(frames, [5, 40, 90]);
        assert_eq!(k.list()[0].params[0].0, ix::ROOT_RY);
        // The contract example round-trips too.
        let c = Keyframes::parse(CONTRACT).unwrap();
        assert_eq!(Keyframes::parse(&c.to_json()).unwrap(), c);
        let v: serde_json::Value = serde_json::from_str(&c.to_json()).unwrap();
        assert_eq!(v["keyframes"][0]["params"]["l_elbow"], 80.0);
        assert_eq!(v["keyframes"][0]["range"], 10);
    }

    #[test]
    fn too_large() {
        let text = format!(r#"{{"keyframes": []}}{}"#, " ".repeat(MAX_BYTES));
        let e = err(&text);
        assert!(matches!(e, KeyframeError::TooLarge { .. }), "{e}");
        assert!(e.to_string().contains("1 MiB"), "{e}");
        assert_one_line(&e);
    }

    #[test]
    fn invalid_json_has_line_and_column() {
        let e = err("{\n  \"keyframes\": [\n    {\"frame\": 1,,}\n  ]\n}");
        match &e {
            KeyframeError::Json { line, column, .. } => {
                assert_eq!(*line, 3);
                assert!(*column > 0);
            }
            other => panic!("{other:?}"),
        }
        let m = e.to_string();
        assert!(
            m.starts_with("invalid keyframes JSON at line 3 column"),
            "{m}"
        );
        assert!(!m.ends_with("column 17"), "location repeated: {m}");
        assert_one_line(&e);
        assert!(matches!(err(""), KeyframeError::Json { .. }));
        assert!(matches!(err("[1, 2]"), KeyframeError::Json { .. }));
        assert!(matches!(
            err(r#"{"keyframes": {"frame": 1}}"#),
            KeyframeError::Json { .. }
        ));
        // Duplicate fields in a keyframe are rejected, not silently merged.
        let e = err(&one("1, \"frame\": 2", "0", r#"{"l_knee": 1}"#));
        assert!(matches!(e, KeyframeError::Json { .. }), "{e}");
        assert!(e.to_string().contains("frame"), "{e}");
    }

    #[test]
    fn missing_list() {
        for text in [r#"{}"#, r#"{"keyframe": []}"#, r#"{"keyframes": null}"#] {
            let e = err(text);
            assert!(matches!(e, KeyframeError::MissingList), "{e}");
            assert!(e.to_string().contains("\"keyframes\""), "{e}");
            assert_one_line(&e);
        }
    }

    #[test]
    fn too_many_keyframes() {
        let list: Vec<Keyframe> = (0..=MAX_KEYFRAMES).map(|f| kf(f, 0, &[(0, 0.0)])).collect();
        let e = Keyframes::from_list(list.clone()).unwrap_err();
        assert!(
            matches!(e, KeyframeError::TooMany { count: 10_001, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("10000"), "{e}");
        // Compact JSON of 10 001 keyframes fits in 1 MiB: the count limit applies.
        let items: Vec<String> = (0..=MAX_KEYFRAMES)
            .map(|f| format!(r#"{{"frame":{f},"range":0,"params":{{"l_knee":1}}}}"#))
            .collect();
        let text = format!(r#"{{"keyframes":[{}]}}"#, items.join(","));
        assert!(text.len() <= MAX_BYTES);
        assert!(matches!(err(&text), KeyframeError::TooMany { .. }));
        // Exactly the limit is fine.
        assert!(Keyframes::from_list(list[..MAX_KEYFRAMES].to_vec()).is_ok());
    }

    #[test]
    fn not_an_object() {
        let e = err(r#"{"keyframes": [{"frame": 1, "range": 0, "params": {"l_knee": 1}}, 7]}"#);
        assert!(
            matches!(e, KeyframeError::NotAnObject { index: 1, ref got } if got == "7"),
            "{e}"
        );
        assert!(
            e.to_string().starts_with("keyframes[1] must be an object"),
            "{e}"
        );
        let e = err(r#"{"keyframes": [["a", {"b": 1}]]}"#);
        assert!(
            matches!(e, KeyframeError::NotAnObject { index: 0, .. }),
            "{e}"
        );
        assert_one_line(&e);
    }

    #[test]
    fn missing_fields() {
        let e = err(r#"{"keyframes": [{"range": 2, "params": {"l_knee": 1}}]}"#);
        assert!(
            matches!(
                e,
                KeyframeError::MissingField {
                    index: 0,
                    frame: None,
                    field: "frame"
                }
            ),
            "{e}"
        );
        assert_eq!(e.to_string(), "keyframes[0]: missing \"frame\"");
        let e = err(r#"{"keyframes": [{"frame": 7, "params": {"l_knee": 1}}]}"#);
        assert_eq!(e.to_string(), "keyframes[0] (frame 7): missing \"range\"");
        let e = err(r#"{"keyframes": [{"frame": 7, "range": 1, "params": null}]}"#);
        assert_eq!(e.to_string(), "keyframes[0] (frame 7): missing \"params\"");
    }

    #[test]
    fn bad_frame_and_range_numbers_are_errors_not_panics() {
        for (frame, got) in [
            ("-1", "-1"),
            ("1e300", "1e+300"),
            ("1.5", "1.5"),
            ("42.0", "42.0"),
            ("18446744073709551616", "1.8446744073709552e+19"),
            ("\"42\"", "a string"),
            ("true", "true"),
            ("[1]", "an array"),
        ] {
            let e = err(&one(frame, "0", r#"{"l_knee": 1}"#));
            match &e {
                KeyframeError::NotAWholeNumber {
                    index: 0,
                    frame: None,
                    field: "frame",
                    got: g,
                } => assert_eq!(g, got),
                other => panic!("{frame}: {other:?}"),
            }
            let m = e.to_string();
            assert!(
                m.starts_with("keyframes[0]: \"frame\" must be a whole number"),
                "{m}"
            );
            assert!(m.ends_with(&format!("got {got}")), "{m}");
            assert_one_line(&e);
        }
        let e = err(&one("3", "-5", r#"{"l_knee": 1}"#));
        assert!(
            matches!(
                e,
                KeyframeError::NotAWholeNumber {
                    frame: Some(3),
                    field: "range",
                    ..
                }
            ),
            "{e}"
        );
        assert!(
            e.to_string()
                .starts_with("keyframes[0] (frame 3): \"range\""),
            "{e}"
        );
        // Numbers JSON cannot represent as f64 are JSON errors.
        assert!(matches!(
            err(&one("1e400", "0", r#"{"l_knee": 1}"#)),
            KeyframeError::Json { .. }
        ));
        assert!(matches!(
            err(&one("1", "0", r#"{"l_knee": -1e400}"#)),
            KeyframeError::Json { .. }
        ));
        // The largest frame and range are accepted and do not overflow anything.
        let big = u64::MAX.to_string();
        let k = Keyframes::parse(&one(&big, &big, r#"{"l_knee": 1}"#)).unwrap();
        assert_eq!(k.list()[0].frame as u64, u64::MAX);
        assert!(k.check_frames(100).is_err());
        let (p, applied) = k.start_pose(0, &[0.0; MOTION_COUNT]);
        assert!(applied);
        assert!(p[ix::L_KNEE] > 0.0 && p[ix::L_KNEE] <= 1.0);
    }

    #[test]
    fn params_not_an_object() {
        let e = err(&one("4", "1", r#"[["l_knee", 1]]"#));
        assert!(
            matches!(e, KeyframeError::ParamsNotAnObject { index: 0, frame: 4, ref got } if got == "an array"),
            "{e}"
        );
        assert!(
            e.to_string()
                .starts_with("keyframes[0] (frame 4): \"params\""),
            "{e}"
        );
        let e = err(&one("4", "1", "12"));
        assert!(matches!(e, KeyframeError::ParamsNotAnObject { .. }), "{e}");
    }

    #[test]
    fn empty_params() {
        let e = err(&one("8", "1", "{}"));
        assert!(
            matches!(e, KeyframeError::EmptyParams { index: 0, frame: 8 }),
            "{e}"
        );
        assert_eq!(
            e.to_string(),
            "keyframes[0] (frame 8): \"params\" is empty; set at least one parameter"
        );
        let e = Keyframes::from_list(vec![kf(1, 0, &[(0, 0.0)]), kf(2, 0, &[])]).unwrap_err();
        assert!(
            matches!(e, KeyframeError::EmptyParams { index: 1, frame: 2 }),
            "{e}"
        );
    }

    #[test]
    fn unknown_parameter() {
        let e = err(&one("42", "10", r#"{"l_elbow": 80, "l_sholder_x": 35}"#));
        match &e {
            KeyframeError::UnknownParameter {
                index: 0,
                frame: 42,
                name,
                suggestion,
            } => {
                assert_eq!(name, "l_sholder_x");
                assert_eq!(*suggestion, Some("l_shoulder_x"));
            }
            other => panic!("{other:?}"),
        }
        let m = e.to_string();
        assert!(
            m.starts_with("keyframes[0] (frame 42): unknown parameter \"l_sholder_x\""),
            "{m}"
        );
        assert!(m.contains("did you mean \"l_shoulder_x\""), "{m}");
        assert!(m.contains("root_tx") && m.contains("r_ankle"), "{m}");
        assert_one_line(&e);
        // Nothing close: no suggestion, still the list.
        let e = err(&one("42", "10", r#"{"wiggle": 1}"#));
        assert!(
            matches!(
                e,
                KeyframeError::UnknownParameter {
                    suggestion: None,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("valid names"), "{e}");
        // Case matters in the file, but the suggestion finds the right name.
        let e = err(&one("42", "10", r#"{"L_ELBOW": 1}"#));
        assert!(e.to_string().contains("did you mean \"l_elbow\""), "{e}");
    }

    #[test]
    fn parameter_index_out_of_range() {
        let e = Keyframes::from_list(vec![kf(3, 0, &[(MOTION_COUNT, 0.0)])]).unwrap_err();
        assert!(
            matches!(
                e,
                KeyframeError::ParameterIndex {
                    index: 0,
                    frame: 3,
                    param: 30
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("index 30"), "{e}");
    }

    #[test]
    fn value_not_a_number() {
        for (v, got) in [
            ("\"80\"", "a string"),
            ("null", "null"),
            ("true", "true"),
            ("[80]", "an array"),
        ] {
            let e = err(&one("42", "10", &format!(r#"{{"l_elbow": {v}}}"#)));
            assert!(
                matches!(e, KeyframeError::NotANumber { index: 0, frame: 42, name: "l_elbow", got: ref g } if g == got),
                "{v}: {e}"
            );
            assert_eq!(
                e.to_string(),
                format!("keyframes[0] (frame 42): l_elbow must be a number, got {got}")
            );
        }
    }

    #[test]
    fn value_not_finite() {
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let e = Keyframes::from_list(vec![kf(6, 2, &[(ix::R_KNEE, v)])]).unwrap_err();
            assert!(
                matches!(
                    e,
                    KeyframeError::NotFinite {
                        index: 0,
                        frame: 6,
                        name: "r_knee",
                        ..
                    }
                ),
                "{e}"
            );
            assert!(
                e.to_string()
                    .starts_with("keyframes[0] (frame 6): r_knee = "),
                "{e}"
            );
        }
    }

    #[test]
    fn value_outside_limits() {
        let e = err(&one("42", "10", r#"{"l_elbow": 200}"#));
        assert!(
            matches!(
                e,
                KeyframeError::OutOfLimits {
                    index: 0,
                    frame: 42,
                    name: "l_elbow",
                    ..
                }
            ),
            "{e}"
        );
        assert_eq!(
            e.to_string(),
            "keyframes[0] (frame 42): l_elbow = 200 deg is outside its limits -5..160 deg"
        );
        let e = err(&one("1", "0", r#"{"root_tx": 1e300}"#));
        assert!(e.to_string().contains("root_tx = "), "{e}");
        assert!(e.to_string().contains("-100000..100000 cm"), "{e}");
        // Limits are inclusive.
        assert!(Keyframes::parse(&one("1", "0", r#"{"l_elbow": -5, "l_knee": 160}"#)).is_ok());
    }

    #[test]
    fn duplicate_parameter() {
        let e = err(&one(
            "42",
            "10",
            r#"{"l_elbow": 80, "l_knee": 3, "l_elbow": 81}"#,
        ));
        assert!(
            matches!(
                e,
                KeyframeError::DuplicateParameter {
                    index: 0,
                    frame: 42,
                    name: "l_elbow"
                }
            ),
            "{e}"
        );
        assert_eq!(
            e.to_string(),
            "keyframes[0] (frame 42): parameter \"l_elbow\" is set twice"
        );
        let e = Keyframes::from_list(vec![kf(1, 0, &[(3, 1.0), (2, 0.0), (3, 2.0)])]).unwrap_err();
        assert!(
            matches!(
                e,
                KeyframeError::DuplicateParameter {
                    name: "root_rx",
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn duplicate_frame() {
        let text = r#"{"keyframes": [
            {"frame": 42, "range": 1, "params": {"l_knee": 1}},
            {"frame": 7, "range": 1, "params": {"l_knee": 1}},
            {"frame": 42, "range": 3, "params": {"r_knee": 1}}]}"#;
        let e = err(text);
        assert!(
            matches!(
                e,
                KeyframeError::DuplicateFrame {
                    first: 0,
                    second: 2,
                    frame: 42
                }
            ),
            "{e}"
        );
        assert_eq!(
            e.to_string(),
            "keyframes[0] and keyframes[2] are both on frame 42; merge them into one keyframe"
        );
    }

    #[test]
    fn frame_outside_clip_names_the_input_position() {
        let text = r#"{"keyframes": [
            {"frame": 130, "range": 1, "params": {"l_knee": 1}},
            {"frame": 7, "range": 1, "params": {"l_knee": 1}}]}"#;
        let k = Keyframes::parse(text).unwrap();
        assert!(k.check_frames(131).is_ok());
        let e = k.check_frames(120).unwrap_err();
        assert!(
            matches!(
                e,
                KeyframeError::OutsideClip {
                    index: 0,
                    frame: 130,
                    frame_count: 120
                }
            ),
            "{e}"
        );
        assert_eq!(
            e.to_string(),
            "keyframes[0] (frame 130) is outside the clip, which has 120 frames numbered from 0"
        );
        let e = k.check_frames(0).unwrap_err();
        assert!(
            matches!(
                e,
                KeyframeError::OutsideClip {
                    index: 1,
                    frame: 7,
                    ..
                }
            ),
            "{e}"
        );
        assert!(Keyframes::default().check_frames(0).is_ok());
    }

    #[test]
    fn every_message_is_one_line() {
        let cases = [
            one("1", "0", r#"{"nope": 1}"#),
            one("1", "0", r#"{"l_knee": 999}"#),
            one("-1", "0", r#"{"l_knee": 1}"#),
            "{\"keyframes\": [1,\n2".to_string(),
            "{}".to_string(),
        ];
        for c in cases {
            assert_one_line(&err(&c));
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn interpolation_weights() {
        // Keyframe at 20, range 4: t = 1 - d/5 for d = 0..=4, untouched beyond.
        let k = Keyframes::from_list(vec![kf(20, 4, &[(ix::L_ELBOW, 100.0)])]).unwrap();
        let mut prev = [0.0; MOTION_COUNT];
        prev[ix::L_ELBOW] = 50.0;
        prev[ix::R_KNEE] = 12.0;
        for (frame, expect) in [
            (20, 100.0),
            (19, 90.0),
            (21, 90.0),
            (18, 80.0),
            (22, 80.0),
            (17, 70.0),
            (16, 60.0),
            (24, 60.0),
        ] {
            let (p, applied) = k.start_pose(frame, &prev);
            assert!(applied, "frame {frame}");
            assert!(
                close(p[ix::L_ELBOW], expect),
                "frame {frame}: {}",
                p[ix::L_ELBOW]
            );
            // Parameters the keyframe does not set keep the previous values.
            for i in (0..MOTION_COUNT).filter(|&i| i != ix::L_ELBOW) {
                assert_eq!(p[i], prev[i], "frame {frame}, parameter {i}");
            }
        }
        // Exactly the keyframe's value on its frame, whatever the previous pose.
        prev[ix::L_ELBOW] = 0.1 + 0.2;
        assert_eq!(k.start_pose(20, &prev).0[ix::L_ELBOW], 100.0);
        for frame in [0, 15, 25, 26, 1000, usize::MAX] {
            let (p, applied) = k.start_pose(frame, &prev);
            assert!(!applied, "frame {frame}");
            assert_eq!(p, prev);
        }
        // Range 0 affects its own frame only.
        let k = Keyframes::from_list(vec![kf(0, 0, &[(ix::L_ELBOW, 100.0)])]).unwrap();
        assert_eq!(
            k.start_pose(0, &prev),
            (
                {
                    let mut p = prev;
                    p[ix::L_ELBOW] = 100.0;
                    p
                },
                true
            )
        );
        assert!(!k.start_pose(1, &prev).1);
        // No keyframes: the previous pose, not applied.
        assert_eq!(Keyframes::default().start_pose(3, &prev), (prev, false));
    }

    #[test]
    fn overlapping_keyframes_choose_the_nearest() {
        let k = Keyframes::from_list(vec![
            kf(10, 10, &[(ix::L_ELBOW, 100.0), (ix::L_KNEE, 40.0)]),
            kf(16, 4, &[(ix::L_ELBOW, 0.0), (ix::R_KNEE, 20.0)]),
            // Far away with a long range: covers everything below.
            kf(100, 200, &[(ix::NECK, 10.0)]),
        ])
        .unwrap();
        let prev = [50.0; MOTION_COUNT];
        // Frame 14: 4 from frame 10 (t = 1 - 4/11), 2 from frame 16 (t = 1 - 2/5).
        let (p, applied) = k.start_pose(14, &prev);
        assert!(applied);
        let t16 = 1.0 - 2.0 / 5.0;
        assert!(close(p[ix::L_ELBOW], 50.0 * (1.0 - t16)));
        // Set by one keyframe only: that one applies, even if farther.
        let t10 = 1.0 - 4.0 / 11.0;
        assert!(close(p[ix::L_KNEE], (1.0 - t10) * 50.0 + t10 * 40.0));
        assert!(close(p[ix::R_KNEE], (1.0 - t16) * 50.0 + t16 * 20.0));
        let t100 = 1.0 - 86.0 / 201.0;
        assert!(close(p[ix::NECK], (1.0 - t100) * 50.0 + t100 * 10.0));
        // Frame 13: equally far (3) from 10 and 16: the later (16) wins.
        let (p, _) = k.start_pose(13, &prev);
        let t16 = 1.0 - 3.0 / 5.0;
        assert!(close(p[ix::L_ELBOW], 50.0 * (1.0 - t16)));
        // Frame 11: 1 from frame 10, 5 from frame 16 (outside its range).
        let (p, _) = k.start_pose(11, &prev);
        let t10 = 1.0 - 1.0 / 11.0;
        assert!(close(p[ix::L_ELBOW], (1.0 - t10) * 50.0 + t10 * 100.0));
        assert_eq!(p[ix::R_KNEE], 50.0);
        // On frame 16 itself its values are exact.
        let (p, _) = k.start_pose(16, &prev);
        assert_eq!(p[ix::L_ELBOW], 0.0);
        assert_eq!(p[ix::R_KNEE], 20.0);
        // Beyond every range.
        assert_eq!(k.start_pose(301, &prev), (prev, false));
        assert!(k.start_pose(300, &prev).1);
    }

    #[test]
    fn at_finds_exact_frames() {
        let k = Keyframes::from_list(vec![
            kf(30, 0, &[(0, 1.0)]),
            kf(10, 0, &[(1, 2.0)]),
            kf(20, 0, &[(2, 3.0)]),
        ])
        .unwrap();
        assert_eq!(k.at(20).unwrap().params, vec![(2, 3.0)]);
        assert_eq!(k.at(10).unwrap().frame, 10);
        assert!(k.at(15).is_none());
        assert!(k.at(usize::MAX).is_none());
    }
}
