//! BVH (Biovision Hierarchy) motion capture: reading, forward kinematics and writing.
//!
//! # What is kept
//!
//! [`Bvh`] keeps the skeleton as a flat list of [`BvhJoint`]s in depth-first file order
//! (parents always before their children, so forward kinematics is one pass over the list),
//! each joint's `CHANNELS` exactly as listed in the file (the order is the rotation order and
//! differs between files and even between joints of one file), and the frame data as one
//! `frames × channels` block of `f64`, rows in file order. Nothing is converted or scaled:
//! units are whatever the file uses, angles stay in degrees.
//!
//! # Semantics
//!
//! A joint's local transform is `Translation(t) · R`, where `t` is its `OFFSET` with every
//! position channel *replacing* the offset on the axis it names (axes not named keep the
//! offset; Bandai Namco files carry the full local translation in position channels on every
//! joint), and `R` is the product of its rotation channels in the order listed, first listed
//! outermost (`Zrotation Xrotation Yrotation` gives `Rz·Rx·Ry`), right-handed, in degrees.
//! The world transform is `parent world · local`. An End Site has an offset only.
//!
//! # Robustness
//!
//! Input is treated as untrusted: parsing never panics and never allocates from a size the
//! file declares. The limits are the `MAX_*` constants of this module; the frame data
//! reservation is additionally capped by what the remaining text could possibly hold.
//!
//! Tolerated: CRLF, lone CR or LF line ends, tabs, any indentation, trailing whitespace, a
//! missing final newline, a UTF-8 byte order mark, keywords and channel names in any letter
//! case, `{`/`}` glued to a word, `Frames:994`, `Frame Time: .0083333`, and frame rows
//! wrapped over several lines (numbers after `Frame Time` are read as a token stream; when
//! the first data line holds exactly one frame, every frame must be on its own line, which
//! gives precise "frame N has K numbers" errors).
//!
//! Rejected, each with a one-line [`BvhError`] naming the problem and the line: numbers
//! after the last declared frame (they mean the frame count or a channel count is wrong,
//! and dropping them silently would hide that), duplicate joint names (real exporters
//! write unique names and name look-ups would become ambiguous), more than one `ROOT`,
//! and a joint without `OFFSET`. Frame indices in messages count from 0, as in
//! [`Bvh::frame`].

use std::collections::HashMap;
use std::fmt;
use std::fs::File;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// Largest file [`Bvh::read`] accepts, checked before reading.
pub const MAX_FILE_BYTES: u64 = 256 * 1024 * 1024;
/// Most joints (End Sites not counted) in one skeleton; real skeletons have 20–100.
pub const MAX_JOINTS: usize = 1024;
/// Most channels on one joint: three positions and three rotations, each at most once.
pub const MAX_CHANNELS_PER_JOINT: usize = 6;
/// Deepest nesting of joints (the root is at depth 1).
pub const MAX_DEPTH: usize = 256;
/// Longest joint name, in bytes.
pub const MAX_NAME_BYTES: usize = 256;
/// Most frames a file may declare (over 23 hours at 120 fps).
pub const MAX_FRAMES: usize = 10_000_000;
/// Most numbers (frames × channels) in the frame data: 1.6 GB of `f64`.
pub const MAX_NUMBERS: usize = 200_000_000;

/// Longest piece of a file token quoted in an error message, in bytes.
const MAX_QUOTED_BYTES: usize = 60;

/// One channel of a joint, as named on its `CHANNELS` line.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Channel {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
}

impl Channel {
    /// All channels, positions first.
    pub const ALL: [Channel; 6] = [
        Channel::Xposition,
        Channel::Yposition,
        Channel::Zposition,
        Channel::Xrotation,
        Channel::Yrotation,
        Channel::Zrotation,
    ];

    /// The BVH spelling, e.g. `"Zrotation"`.
    pub fn name(&self) -> &'static str {
        match self {
            Channel::Xposition => "Xposition",
            Channel::Yposition => "Yposition",
            Channel::Zposition => "Zposition",
            Channel::Xrotation => "Xrotation",
            Channel::Yrotation => "Yrotation",
            Channel::Zrotation => "Zrotation",
        }
    }

    /// The channel spelled `name`, ignoring ASCII letter case.
    pub fn from_name(name: &str) -> Option<Channel> {
        Channel::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(name))
    }

    /// The axis the channel acts on: 0 for X, 1 for Y, 2 for Z.
    pub fn axis(&self) -> usize {
        match self {
            Channel::Xposition | Channel::Xrotation => 0,
            Channel::Yposition | Channel::Yrotation => 1,
            Channel::Zposition | Channel::Zrotation => 2,
        }
    }

    /// Whether this is a position (translation) channel rather than a rotation.
    pub fn is_position(&self) -> bool {
        matches!(
            self,
            Channel::Xposition | Channel::Yposition | Channel::Zposition
        )
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One joint (`ROOT` or `JOINT`) of the hierarchy.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhJoint {
    /// Name as written in the file: one token, no whitespace or braces.
    pub name: String,
    /// Index of the parent in [`Bvh::joints`]; `None` only for the root, joint 0.
    pub parent: Option<usize>,
    /// `OFFSET` from the parent, in file units.
    pub offset: [f64; 3],
    /// Channels in the order listed; this is also the rotation order.
    pub channels: Vec<Channel>,
    /// Index of this joint's first channel in a frame row.
    pub channel_offset: usize,
    /// `OFFSET` of the joint's End Site, if it has one.
    pub end_site: Option<[f64; 3]>,
}

/// A parsed BVH file: skeleton, frame time and frame data.
///
/// `joints` and `frame_time` are public for reading. Changing them so that they no longer
/// match the frame data never panics, but makes forward kinematics and [`Bvh::write`]
/// meaningless; build a changed file with [`Bvh::from_parts`], which checks consistency.
#[derive(Clone)]
pub struct Bvh {
    /// Joints in depth-first file order, parents before children.
    pub joints: Vec<BvhJoint>,
    /// Seconds per frame (`Frame Time`), finite and positive.
    pub frame_time: f64,
    /// Frame data, `frame_count × channels` numbers, one row per frame.
    data: Vec<f64>,
    /// Numbers per frame row; never 0.
    channels: usize,
}

/// Why a BVH file could not be read or a [`Bvh`] could not be built. `Display` is one line.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BvhError {
    /// The file could not be opened or read.
    #[error("cannot read {}: {error}", path.display())]
    Io {
        path: PathBuf,
        /// Not a `#[source]`: the one-line message already carries it.
        error: io::Error,
    },
    /// The file is larger than [`MAX_FILE_BYTES`].
    #[error("{} is {size} bytes, more than the limit of {limit} bytes", path.display())]
    FileTooLarge {
        path: PathBuf,
        size: u64,
        limit: u64,
    },
    /// The text holds nothing but whitespace.
    #[error("file is empty")]
    Empty,
    /// The hierarchy or the MOTION header is malformed, or a limit is exceeded.
    #[error("line {line}: {message}")]
    Syntax { line: usize, message: String },
    /// A token where a number belongs is not a number (`token` is quoted).
    #[error("line {line}: {token} is not a number")]
    NotANumber { line: usize, token: String },
    /// A number is NaN or infinite (`token` is quoted).
    #[error("line {line}: {token} is not a finite number")]
    NotFinite { line: usize, token: String },
    /// `Frames:` is negative.
    #[error("line {line}: frame count {count} is negative")]
    NegativeFrameCount { line: usize, count: String },
    /// `Frames:` is more than [`MAX_FRAMES`].
    #[error("line {line}: declared {declared} frames, more than the limit of {limit}")]
    TooManyFrames {
        line: usize,
        declared: String,
        limit: usize,
    },
    /// Frames × channels is more than [`MAX_NUMBERS`].
    #[error(
        "line {line}: declared {frames} frames of {channels} numbers, \
         more than the limit of {limit} numbers"
    )]
    TooManyNumbers {
        line: usize,
        frames: usize,
        channels: usize,
        limit: usize,
    },
    /// `Frame Time` is zero, negative or not finite.
    #[error("line {line}: Frame Time {value} must be positive and finite")]
    BadFrameTime { line: usize, value: String },
    /// The text ends before all declared frames are complete.
    #[error("expected {frames} frames of {channels} numbers, file ends after {complete} frames")]
    Truncated {
        frames: usize,
        channels: usize,
        complete: usize,
    },
    /// With one frame per line, a line holds the wrong count of numbers.
    #[error("line {line}: frame {frame} has {found} numbers, expected {expected}")]
    RowLength {
        line: usize,
        frame: usize,
        found: usize,
        expected: usize,
    },
    /// Numbers follow the last declared frame.
    #[error(
        "line {line}: data continues after the declared {frames} frames of {channels} numbers"
    )]
    ExtraData {
        line: usize,
        frames: usize,
        channels: usize,
    },
    /// [`Bvh::from_parts`] was given inconsistent parts.
    #[error("invalid BVH parts: {0}")]
    Invalid(String),
}

impl Bvh {
    /// Parses BVH text. Never panics; see the module documentation for what is tolerated.
    ///
    /// # Errors
    ///
    /// Any [`BvhError`] but `Io`, `FileTooLarge` and `Invalid`, naming the first problem.
    pub fn parse(text: &str) -> Result<Bvh, BvhError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lex = Lexer::new(text);
        let (joints, channels) = parse_hierarchy(&mut lex)?;
        let (frame_time, data) = parse_motion(&mut lex, channels)?;
        debug_assert!(validate_skeleton(&joints).is_ok());
        Ok(Bvh {
            joints,
            frame_time,
            data,
            channels,
        })
    }

    /// Reads and parses a BVH file, refusing files over [`MAX_FILE_BYTES`] before reading.
    /// Text that is not valid UTF-8 is read lossily (a Latin-1 joint name should not stop a
    /// file from loading; binary garbage fails in parsing anyway).
    ///
    /// # Errors
    ///
    /// [`BvhError::Io`] naming the path, [`BvhError::FileTooLarge`], or a parse error.
    pub fn read(path: &Path) -> Result<Bvh, BvhError> {
        let io_error = |error| BvhError::Io {
            path: path.to_path_buf(),
            error,
        };
        let too_large = |size| BvhError::FileTooLarge {
            path: path.to_path_buf(),
            size,
            limit: MAX_FILE_BYTES,
        };
        let file = File::open(path).map_err(io_error)?;
        let size = file.metadata().map_err(io_error)?.len();
        if size > MAX_FILE_BYTES {
            return Err(too_large(size));
        }
        let mut bytes = Vec::new();
        // `take` guards against files that grow, or lie about their size, while read.
        file.take(MAX_FILE_BYTES + 1)
            .read_to_end(&mut bytes)
            .map_err(io_error)?;
        if bytes.len() as u64 > MAX_FILE_BYTES {
            return Err(too_large(bytes.len() as u64));
        }
        let text = match String::from_utf8(bytes) {
            Ok(text) => text,
            Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
        };
        Bvh::parse(&text)
    }

    /// Builds a `Bvh` from its parts, checking everything [`Bvh::parse`] guarantees: joint 0
    /// is the only root, joints are in depth-first order, names are unique single tokens,
    /// each joint has at most six distinct channels, `channel_offset`s count the channels
    /// of the joints before, there is at least one channel, `frame_time` is positive and
    /// finite, and `data` is whole frames of finite numbers within the limits.
    ///
    /// # Errors
    ///
    /// [`BvhError::Invalid`] naming the first inconsistency.
    pub fn from_parts(
        joints: Vec<BvhJoint>,
        frame_time: f64,
        data: Vec<f64>,
    ) -> Result<Bvh, BvhError> {
        let channels = validate_skeleton(&joints).map_err(BvhError::Invalid)?;
        if !(frame_time.is_finite() && frame_time > 0.0) {
            return Err(BvhError::Invalid(format!(
                "frame_time {frame_time} must be positive and finite"
            )));
        }
        if !data.len().is_multiple_of(channels) {
            return Err(BvhError::Invalid(format!(
                "{} numbers of frame data are not whole frames of {channels} channels",
                data.len()
            )));
        }
        if data.len() / channels > MAX_FRAMES || data.len() > MAX_NUMBERS {
            return Err(BvhError::Invalid(format!(
                "{} frames of {channels} numbers exceed the limits of {MAX_FRAMES} frames \
                 and {MAX_NUMBERS} numbers",
                data.len() / channels
            )));
        }
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(BvhError::Invalid(format!(
                "frame {} channel {} is {}, not a finite number",
                i / channels,
                i % channels,
                data[i]
            )));
        }
        Ok(Bvh {
            joints,
            frame_time,
            data,
            channels,
        })
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.data.len() / self.channels
    }

    /// Numbers per frame: the total of all joints' channels.
    pub fn channel_count(&self) -> usize {
        self.channels
    }

    /// Frames per second, `1 / frame_time`.
    pub fn fps(&self) -> f64 {
        1.0 / self.frame_time
    }

    /// The channel values of frame `i`, in file order.
    ///
    /// # Panics
    ///
    /// If `i >= self.frame_count()`.
    pub fn frame(&self, i: usize) -> &[f64] {
        assert!(
            i < self.frame_count(),
            "frame {i} out of range: the motion has {} frames",
            self.frame_count()
        );
        &self.data[i * self.channels..(i + 1) * self.channels]
    }

    /// All frame data, `frame_count() × channel_count()` numbers, one row per frame.
    pub fn data(&self) -> &[f64] {
        &self.data
    }

    /// Index of the joint called `name` (exact match).
    pub fn find(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The transform of joint `joint` relative to its parent at frame `frame`.
    ///
    /// # Panics
    ///
    /// If `joint` or `frame` is out of range.
    pub fn local_transform(&self, joint: usize, frame: usize) -> Isometry3<f64> {
        local_transform(&self.joints[joint], self.frame(frame))
    }

    /// World transforms of all joints at frame `frame`, one per joint in joint order,
    /// written into `out` (cleared first; its allocation is reused).
    ///
    /// # Panics
    ///
    /// If `frame >= self.frame_count()`.
    pub fn world_transforms(&self, frame: usize, out: &mut Vec<Isometry3<f64>>) {
        let row = self.frame(frame);
        out.clear();
        out.reserve(self.joints.len());
        for (i, joint) in self.joints.iter().enumerate() {
            let local = local_transform(joint, row);
            let world = match joint.parent {
                // Parents come first, so `out[p]` is already computed.
                Some(p) if p < i => out[p] * local,
                _ => local,
            };
            out.push(world);
        }
    }

    /// World positions of the joints (not the End Sites) at frame `frame`.
    ///
    /// # Panics
    ///
    /// If `frame >= self.frame_count()`.
    pub fn joint_positions(&self, frame: usize) -> Vec<Point3<f64>> {
        let mut world = Vec::new();
        self.world_transforms(frame, &mut world);
        world
            .iter()
            .map(|iso| Point3::from(iso.translation.vector))
            .collect()
    }

    /// For each joint, the world position of its End Site at frame `frame`, if it has one.
    ///
    /// # Panics
    ///
    /// If `frame >= self.frame_count()`.
    pub fn end_site_positions(&self, frame: usize) -> Vec<Option<Point3<f64>>> {
        let mut world = Vec::new();
        self.world_transforms(frame, &mut world);
        self.joints
            .iter()
            .zip(&world)
            .map(|(joint, iso)| joint.end_site.map(|e| iso * Point3::from(e)))
            .collect()
    }

    /// Writes standard BVH text: tab-indented HIERARCHY, then MOTION with one line per frame.
    /// Numbers get six decimals (trailing zeros dropped), so reading back reproduces joint
    /// positions to well within 1e-4 units; the frame time is written exactly.
    pub fn write<W: Write>(&self, mut w: W) -> io::Result<()> {
        self.write_chunks(|chunk| w.write_all(chunk.as_bytes()))?;
        w.flush()
    }

    /// The text [`Bvh::write`] produces.
    pub fn to_bvh_string(&self) -> String {
        let mut out = String::new();
        // Appending to a String cannot fail.
        let _ = self.write_chunks(|chunk| {
            out.push_str(chunk);
            Ok(())
        });
        out
    }

    /// Produces the BVH text in pieces of about 64 KiB, so that writing a large motion
    /// does not hold all of its text in memory.
    fn write_chunks(&self, mut sink: impl FnMut(&str) -> io::Result<()>) -> io::Result<()> {
        const CHUNK: usize = 1 << 16;
        let mut buf = String::with_capacity(CHUNK + 4096);
        buf.push_str("HIERARCHY\n");
        let mut open: Vec<usize> = Vec::new();
        for (i, joint) in self.joints.iter().enumerate() {
            while let Some(&top) = open.last() {
                if Some(top) == joint.parent {
                    break;
                }
                open.pop();
                self.close_joint(&mut buf, top, open.len());
            }
            let depth = open.len();
            indent(&mut buf, depth);
            buf.push_str(if joint.parent.is_none() {
                "ROOT "
            } else {
                "JOINT "
            });
            buf.push_str(&joint.name);
            buf.push('\n');
            indent(&mut buf, depth);
            buf.push_str("{\n");
            indent(&mut buf, depth + 1);
            push_offset(&mut buf, joint.offset);
            indent(&mut buf, depth + 1);
            buf.push_str("CHANNELS ");
            push_display(&mut buf, joint.channels.len());
            for channel in &joint.channels {
                buf.push(' ');
                buf.push_str(channel.name());
            }
            buf.push('\n');
            open.push(i);
        }
        while let Some(top) = open.pop() {
            self.close_joint(&mut buf, top, open.len());
        }
        buf.push_str("MOTION\nFrames: ");
        push_display(&mut buf, self.frame_count());
        buf.push_str("\nFrame Time: ");
        // `Display` of f64 is the shortest text that reads back to the same value.
        push_display(&mut buf, self.frame_time);
        buf.push('\n');
        for row in self.data.chunks_exact(self.channels.max(1)) {
            for (k, &v) in row.iter().enumerate() {
                if k > 0 {
                    buf.push(' ');
                }
                push_number(&mut buf, v);
            }
            buf.push('\n');
            if buf.len() >= CHUNK {
                sink(&buf)?;
                buf.clear();
            }
        }
        sink(&buf)
    }

    /// Writes joint `i`'s End Site, if any, and its closing brace at `depth`.
    fn close_joint(&self, buf: &mut String, i: usize, depth: usize) {
        if let Some(end) = self.joints[i].end_site {
            indent(buf, depth + 1);
            buf.push_str("End Site\n");
            indent(buf, depth + 1);
            buf.push_str("{\n");
            indent(buf, depth + 2);
            push_offset(buf, end);
            indent(buf, depth + 1);
            buf.push_str("}\n");
        }
        indent(buf, depth);
        buf.push_str("}\n");
    }
}

impl fmt::Debug for Bvh {
    /// Summarises instead of dumping the (possibly huge) frame data.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Bvh")
            .field("joints", &self.joints)
            .field("frame_time", &self.frame_time)
            .field("frame_count", &self.frame_count())
            .field("channel_count", &self.channels)
            .finish()
    }
}

/// A joint's transform relative to its parent for one frame row. Values missing from the
/// row (only possible after editing the public fields) count as 0.
fn local_transform(joint: &BvhJoint, row: &[f64]) -> Isometry3<f64> {
    let mut t = Vector3::from(joint.offset);
    let mut r = UnitQuaternion::identity();
    for (k, &channel) in joint.channels.iter().enumerate() {
        let v = joint
            .channel_offset
            .checked_add(k)
            .and_then(|c| row.get(c))
            .copied()
            .unwrap_or(0.0);
        if channel.is_position() {
            t[channel.axis()] = v;
        } else {
            let axis = match channel.axis() {
                0 => Vector3::x_axis(),
                1 => Vector3::y_axis(),
                _ => Vector3::z_axis(),
            };
            r *= UnitQuaternion::from_axis_angle(&axis, v.to_radians());
        }
    }
    Isometry3::from_parts(Translation3::from(t), r)
}

fn indent(buf: &mut String, depth: usize) {
    buf.extend(std::iter::repeat_n('\t', depth));
}

fn push_display(buf: &mut String, value: impl fmt::Display) {
    use fmt::Write as _;
    // Writing to a String cannot fail.
    let _ = write!(buf, "{value}");
}

/// Appends `v` with six decimals, trailing zeros and a bare `-0` removed.
fn push_number(buf: &mut String, v: f64) {
    use fmt::Write as _;
    let start = buf.len();
    let _ = write!(buf, "{v:.6}");
    if buf[start..].contains('.') {
        let trimmed = buf.trim_end_matches('0').trim_end_matches('.').len();
        buf.truncate(trimmed);
    }
    if &buf[start..] == "-0" {
        buf.truncate(start);
        buf.push('0');
    }
}

fn push_offset(buf: &mut String, offset: [f64; 3]) {
    buf.push_str("OFFSET");
    for v in offset {
        buf.push(' ');
        push_number(buf, v);
    }
    buf.push('\n');
}

// ---------------------------------------------------------------------------------------
// Validation shared by `from_parts` (and checked against `parse` in debug builds).

/// Whether `c` separates tokens: the ASCII whitespace the lexer skips.
fn is_separator(c: u8) -> bool {
    matches!(c, b' ' | b'\t' | b'\n' | b'\r' | 0x0B | 0x0C)
}

/// Checks the skeleton invariants and returns the total channel count.
fn validate_skeleton(joints: &[BvhJoint]) -> Result<usize, String> {
    if joints.is_empty() {
        return Err("the skeleton has no joints".into());
    }
    if joints.len() > MAX_JOINTS {
        return Err(format!(
            "{} joints, more than the limit of {MAX_JOINTS}",
            joints.len()
        ));
    }
    let mut names: HashMap<&str, usize> = HashMap::new();
    let mut open: Vec<usize> = Vec::new();
    let mut total = 0;
    for (i, joint) in joints.iter().enumerate() {
        let name = &joint.name;
        let shown = show_name(name);
        if name.is_empty()
            || name
                .bytes()
                .any(|c| is_separator(c) || c == b'{' || c == b'}')
        {
            return Err(format!(
                "joint {i} name '{shown}' is not one token without whitespace or braces"
            ));
        }
        if name.len() > MAX_NAME_BYTES {
            return Err(format!(
                "joint {i} name is {} bytes, more than the limit of {MAX_NAME_BYTES}",
                name.len()
            ));
        }
        if let Some(first) = names.insert(name, i) {
            return Err(format!("joints {first} and {i} are both called {shown}"));
        }
        match (i, joint.parent) {
            (0, None) => {}
            (0, Some(p)) => {
                return Err(format!("the root joint {shown} has parent {p}"));
            }
            (_, None) => {
                return Err(format!(
                    "joint {i} ({shown}) has no parent: only joint 0 may be the root"
                ));
            }
            (_, Some(p)) => {
                while let Some(&top) = open.last() {
                    if top == p {
                        break;
                    }
                    open.pop();
                }
                if open.is_empty() {
                    return Err(format!(
                        "joint {i} ({shown}) has parent {p}, but joints must be in \
                         depth-first order with parents before children"
                    ));
                }
            }
        }
        if open.len() >= MAX_DEPTH {
            return Err(format!(
                "joint {i} ({shown}) is nested deeper than the limit of {MAX_DEPTH}"
            ));
        }
        open.push(i);
        if joint.channels.len() > MAX_CHANNELS_PER_JOINT {
            return Err(format!(
                "joint {shown} has {} channels, more than the limit of {MAX_CHANNELS_PER_JOINT}",
                joint.channels.len()
            ));
        }
        for (k, c) in joint.channels.iter().enumerate() {
            if joint.channels[..k].contains(c) {
                return Err(format!("joint {shown} lists channel {c} twice"));
            }
        }
        if joint.channel_offset != total {
            return Err(format!(
                "joint {i} ({shown}) has channel_offset {}, expected {total}",
                joint.channel_offset
            ));
        }
        total += joint.channels.len();
        let finite = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        if !finite(&joint.offset) || !joint.end_site.as_ref().is_none_or(finite) {
            return Err(format!("joint {shown} has a non-finite offset"));
        }
    }
    if total == 0 {
        return Err("the skeleton has no channels".into());
    }
    Ok(total)
}

// ---------------------------------------------------------------------------------------
// Lexer: whitespace-separated tokens with line numbers; `{` and `}` are tokens of their own.

#[derive(Clone, Copy)]
struct Token<'a> {
    text: &'a str,
    line: usize,
}

impl Token<'_> {
    /// Whether the token is the keyword `kw`, ignoring ASCII case.
    fn is(&self, kw: &str) -> bool {
        self.text.eq_ignore_ascii_case(kw)
    }

    fn quoted(&self) -> String {
        quote(self.text)
    }
}

#[derive(Clone)]
struct Lexer<'a> {
    text: &'a str,
    pos: usize,
    /// Line of the next unread character, counting from 1.
    line: usize,
}

impl<'a> Lexer<'a> {
    fn new(text: &'a str) -> Self {
        Lexer {
            text,
            pos: 0,
            line: 1,
        }
    }

    fn next_token(&mut self) -> Option<Token<'a>> {
        let bytes = self.text.as_bytes();
        while let Some(&c) = bytes.get(self.pos) {
            match c {
                b'\n' => self.line += 1,
                // A lone CR ends a line too; CRLF counts once, at its LF.
                b'\r' if bytes.get(self.pos + 1) != Some(&b'\n') => self.line += 1,
                c if is_separator(c) => {}
                _ => break,
            }
            self.pos += 1;
        }
        let start = self.pos;
        match bytes.get(start)? {
            b'{' | b'}' => self.pos += 1,
            _ => {
                while let Some(&c) = bytes.get(self.pos) {
                    if is_separator(c) || c == b'{' || c == b'}' {
                        break;
                    }
                    self.pos += 1;
                }
            }
        }
        // Token bounds are at ASCII bytes or the ends, so always on char boundaries.
        let text = self.text.get(start..self.pos)?;
        Some(Token {
            text,
            line: self.line,
        })
    }

    fn peek(&self) -> Option<Token<'a>> {
        self.clone().next_token()
    }

    /// Bytes not yet read.
    fn remaining(&self) -> usize {
        self.text.len().saturating_sub(self.pos)
    }
}

/// `text` in single quotes, shortened and with control characters escaped, for messages.
fn quote(text: &str) -> String {
    format!("'{}'", show_name(text))
}

/// `text` shortened and with control characters escaped, for messages.
fn show_name(text: &str) -> String {
    let mut out = String::new();
    for c in text.chars() {
        if out.len() >= MAX_QUOTED_BYTES {
            out.push('…');
            break;
        }
        if c.is_control() || c.is_whitespace() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

fn syntax(line: usize, message: impl Into<String>) -> BvhError {
    BvhError::Syntax {
        line,
        message: message.into(),
    }
}

/// A finite number, or the error naming the token.
fn number(tok: Token<'_>) -> Result<f64, BvhError> {
    match tok.text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(BvhError::NotFinite {
            line: tok.line,
            token: tok.quoted(),
        }),
        Err(_) => Err(BvhError::NotANumber {
            line: tok.line,
            token: tok.quoted(),
        }),
    }
}

/// Whether the token is a structural word of the hierarchy rather than a value.
fn is_structural(tok: Token<'_>) -> bool {
    [
        "{", "}", "ROOT", "JOINT", "End", "OFFSET", "CHANNELS", "MOTION",
    ]
    .iter()
    .any(|kw| tok.is(kw))
}

// ---------------------------------------------------------------------------------------
// HIERARCHY

/// A joint whose `{` has been read but not its `}`.
#[derive(Clone, Copy)]
struct Open {
    joint: usize,
    has_offset: bool,
    has_channels: bool,
    has_children: bool,
}

/// Parses from `HIERARCHY` to the root's closing brace; returns the joints and the total
/// channel count.
fn parse_hierarchy(lex: &mut Lexer<'_>) -> Result<(Vec<BvhJoint>, usize), BvhError> {
    let first = lex.next_token().ok_or(BvhError::Empty)?;
    if !first.is("HIERARCHY") {
        return Err(syntax(
            first.line,
            format!("expected HIERARCHY, found {}", first.quoted()),
        ));
    }
    let root = lex
        .next_token()
        .ok_or_else(|| syntax(lex.line, "file ends after HIERARCHY: missing ROOT"))?;
    if !root.is("ROOT") {
        return Err(syntax(
            root.line,
            format!("expected ROOT after HIERARCHY, found {}", root.quoted()),
        ));
    }

    let mut joints: Vec<BvhJoint> = Vec::new();
    let mut names: HashMap<&str, usize> = HashMap::new();
    let mut stack: Vec<Open> = Vec::new();
    let mut total_channels = 0;
    open_joint(lex, root, None, &mut joints, &mut names, &mut stack, 0)?;

    while let Some(&top) = stack.last() {
        let j = top.joint;
        let name = show_name(&joints[j].name);
        let Some(tok) = lex.next_token() else {
            return Err(syntax(
                lex.line,
                format!("file ends inside joint {name}: missing '}}'"),
            ));
        };
        let top_mut = stack.len() - 1;
        if tok.is("OFFSET") {
            if top.has_offset {
                return Err(syntax(
                    tok.line,
                    format!("joint {name} has a second OFFSET"),
                ));
            }
            joints[j].offset = read_offset(lex, tok, &name)?;
            stack[top_mut].has_offset = true;
        } else if tok.is("CHANNELS") {
            if top.has_channels {
                return Err(syntax(
                    tok.line,
                    format!("joint {name} has a second CHANNELS line"),
                ));
            }
            if top.has_children {
                return Err(syntax(
                    tok.line,
                    format!("CHANNELS of joint {name} must come before its child joints"),
                ));
            }
            let channels = read_channels(lex, tok, &name)?;
            total_channels += channels.len();
            joints[j].channels = channels;
            stack[top_mut].has_channels = true;
        } else if tok.is("JOINT") {
            stack[top_mut].has_children = true;
            open_joint(
                lex,
                tok,
                Some(j),
                &mut joints,
                &mut names,
                &mut stack,
                total_channels,
            )?;
        } else if tok.is("End") {
            if joints[j].end_site.is_some() {
                return Err(syntax(
                    tok.line,
                    format!("joint {name} has a second End Site"),
                ));
            }
            joints[j].end_site = Some(read_end_site(lex, tok, &name)?);
        } else if tok.text == "}" {
            if !top.has_offset {
                return Err(syntax(tok.line, format!("joint {name} has no OFFSET")));
            }
            stack.pop();
        } else if tok.is("MOTION") || tok.is("ROOT") || tok.is("HIERARCHY") {
            return Err(syntax(
                tok.line,
                format!(
                    "{} inside joint {name}: missing '}}'",
                    tok.text.to_ascii_uppercase()
                ),
            ));
        } else {
            return Err(syntax(
                tok.line,
                format!("unknown keyword {} in joint {name}", tok.quoted()),
            ));
        }
    }
    Ok((joints, total_channels))
}

/// Reads a joint's name and `{` after `keyword` (ROOT or JOINT) and opens it.
fn open_joint<'a>(
    lex: &mut Lexer<'a>,
    keyword: Token<'a>,
    parent: Option<usize>,
    joints: &mut Vec<BvhJoint>,
    names: &mut HashMap<&'a str, usize>,
    stack: &mut Vec<Open>,
    channel_offset: usize,
) -> Result<(), BvhError> {
    let kw = keyword.text.to_ascii_uppercase();
    let name = lex.next_token().ok_or_else(|| {
        syntax(
            lex.line,
            format!("file ends after {kw}: missing joint name"),
        )
    })?;
    if name.text == "{" || name.text == "}" {
        return Err(syntax(name.line, format!("{kw} has no name")));
    }
    let shown = show_name(name.text);
    if name.text.len() > MAX_NAME_BYTES {
        return Err(syntax(
            name.line,
            format!(
                "joint name {shown} is {} bytes long, more than the limit of {MAX_NAME_BYTES}",
                name.text.len()
            ),
        ));
    }
    if let Some(first) = names.insert(name.text, name.line) {
        return Err(syntax(
            name.line,
            format!("duplicate joint name {shown} (first declared on line {first})"),
        ));
    }
    if joints.len() >= MAX_JOINTS {
        return Err(syntax(
            keyword.line,
            format!("more than the limit of {MAX_JOINTS} joints"),
        ));
    }
    if stack.len() >= MAX_DEPTH {
        return Err(syntax(
            keyword.line,
            format!("joint {shown} is nested deeper than the limit of {MAX_DEPTH}"),
        ));
    }
    match lex.next_token() {
        Some(brace) if brace.text == "{" => {}
        Some(other) => {
            return Err(syntax(
                other.line,
                format!("expected '{{' after {kw} {shown}, found {}", other.quoted()),
            ));
        }
        None => {
            return Err(syntax(
                lex.line,
                format!("file ends after {kw} {shown}: missing '{{'"),
            ));
        }
    }
    stack.push(Open {
        joint: joints.len(),
        has_offset: false,
        has_channels: false,
        has_children: false,
    });
    joints.push(BvhJoint {
        name: name.text.to_owned(),
        parent,
        offset: [0.0; 3],
        channels: Vec::new(),
        channel_offset,
        end_site: None,
    });
    Ok(())
}

/// Reads the three numbers after `OFFSET`.
fn read_offset(lex: &mut Lexer<'_>, keyword: Token<'_>, owner: &str) -> Result<[f64; 3], BvhError> {
    let mut offset = [0.0; 3];
    for (k, v) in offset.iter_mut().enumerate() {
        let Some(tok) = lex.next_token() else {
            return Err(syntax(
                lex.line,
                format!("file ends in the OFFSET of {owner}"),
            ));
        };
        if tok.line != keyword.line && tok.text.parse::<f64>().is_err() {
            return Err(syntax(
                keyword.line,
                format!("OFFSET of {owner} has {k} numbers, expected 3"),
            ));
        }
        *v = number(tok)?;
    }
    Ok(offset)
}

/// Reads the count and names after `CHANNELS`.
fn read_channels(
    lex: &mut Lexer<'_>,
    keyword: Token<'_>,
    joint: &str,
) -> Result<Vec<Channel>, BvhError> {
    let Some(count_tok) = lex.next_token() else {
        return Err(syntax(
            lex.line,
            format!("file ends in the CHANNELS of joint {joint}"),
        ));
    };
    let count = match count_tok.text.parse::<usize>() {
        Ok(n) if n <= MAX_CHANNELS_PER_JOINT => n,
        Err(_) if !count_tok.text.bytes().all(|c| c.is_ascii_digit()) => {
            return Err(syntax(
                count_tok.line,
                format!(
                    "channel count {} of joint {joint} is not a whole number",
                    count_tok.quoted()
                ),
            ));
        }
        _ => {
            return Err(syntax(
                count_tok.line,
                format!(
                    "joint {joint} declares {} channels, more than the limit of \
                     {MAX_CHANNELS_PER_JOINT}",
                    count_tok.text
                ),
            ));
        }
    };
    let mut channels = Vec::with_capacity(count);
    for listed in 0..count {
        let Some(tok) = lex.next_token() else {
            return Err(syntax(
                lex.line,
                format!("file ends in the CHANNELS of joint {joint}"),
            ));
        };
        let Some(channel) = Channel::from_name(tok.text) else {
            // A keyword, or a word on a later line, means the list is short; a word on
            // the CHANNELS line itself is a misspelt channel.
            if is_structural(tok) || tok.line != keyword.line {
                return Err(syntax(
                    keyword.line,
                    format!("joint {joint} declares {count} channels but lists {listed}"),
                ));
            }
            return Err(syntax(
                tok.line,
                format!("unknown channel {} on joint {joint}", tok.quoted()),
            ));
        };
        if channels.contains(&channel) {
            return Err(syntax(
                tok.line,
                format!("channel {channel} is listed twice on joint {joint}"),
            ));
        }
        channels.push(channel);
    }
    if let Some(next) = lex.peek() {
        if next.line == keyword.line && Channel::from_name(next.text).is_some() {
            return Err(syntax(
                next.line,
                format!("joint {joint} declares {count} channels but lists more"),
            ));
        }
    }
    Ok(channels)
}

/// Reads `Site { OFFSET x y z }` after `End`.
fn read_end_site(lex: &mut Lexer<'_>, end: Token<'_>, joint: &str) -> Result<[f64; 3], BvhError> {
    let owner = format!("the End Site of joint {joint}");
    let eof = |lex: &Lexer<'_>| syntax(lex.line, format!("file ends in {owner}"));
    let site = lex.next_token().ok_or_else(|| eof(lex))?;
    if !site.is("Site") {
        return Err(syntax(
            site.line,
            format!("expected 'Site' after 'End', found {}", site.quoted()),
        ));
    }
    let brace = lex.next_token().ok_or_else(|| eof(lex))?;
    if brace.text != "{" {
        return Err(syntax(
            brace.line,
            format!("expected '{{' after End Site, found {}", brace.quoted()),
        ));
    }
    let keyword = lex.next_token().ok_or_else(|| eof(lex))?;
    if !keyword.is("OFFSET") {
        let problem = if keyword.text == "}" {
            format!("{owner} has no OFFSET")
        } else {
            format!("expected OFFSET in {owner}, found {}", keyword.quoted())
        };
        return Err(syntax(keyword.line, problem));
    }
    let offset = read_offset(lex, keyword, &owner)?;
    let close = lex.next_token().ok_or_else(|| eof(lex))?;
    if close.text != "}" {
        return Err(syntax(
            close.line,
            format!(
                "expected '}}' to close {owner} (opened on line {}), found {}",
                end.line,
                close.quoted()
            ),
        ));
    }
    Ok(offset)
}

// ---------------------------------------------------------------------------------------
// MOTION

/// Parses from `MOTION` to the end; returns the frame time and the frame data.
fn parse_motion(lex: &mut Lexer<'_>, channels: usize) -> Result<(f64, Vec<f64>), BvhError> {
    let Some(motion) = lex.next_token() else {
        return Err(syntax(
            lex.line,
            "file ends after the hierarchy: missing MOTION section",
        ));
    };
    if !motion.is("MOTION") {
        let problem = if motion.is("ROOT") {
            "a second ROOT is not supported".to_owned()
        } else if motion.text == "}" {
            "unbalanced braces: '}' without a matching '{'".to_owned()
        } else {
            format!(
                "expected MOTION after the hierarchy, found {}",
                motion.quoted()
            )
        };
        return Err(syntax(motion.line, problem));
    }
    if channels == 0 {
        return Err(syntax(motion.line, "the skeleton has no channels"));
    }

    let count = keyed_value(lex, "Frames", "Frames:")?;
    let frames = frame_count(count)?;
    let total = frames
        .checked_mul(channels)
        .filter(|&n| n <= MAX_NUMBERS)
        .ok_or(BvhError::TooManyNumbers {
            line: count.line,
            frames,
            channels,
            limit: MAX_NUMBERS,
        })?;

    match lex.next_token() {
        Some(tok) if tok.is("Frame") => {}
        Some(tok) => {
            return Err(syntax(
                tok.line,
                format!("expected 'Frame Time:', found {}", tok.quoted()),
            ));
        }
        None => return Err(syntax(lex.line, "file ends before 'Frame Time:'")),
    }
    let time = keyed_value(lex, "Time", "Frame Time:")?;
    let frame_time = number(time).map_err(|e| match e {
        BvhError::NotFinite { .. } => BvhError::BadFrameTime {
            line: time.line,
            value: show_name(time.text),
        },
        e => e,
    })?;
    if frame_time <= 0.0 {
        return Err(BvhError::BadFrameTime {
            line: time.line,
            value: show_name(time.text),
        });
    }

    // Every number takes at least one character and one separator, so the rest of the
    // text bounds the reservation whatever the header claims.
    let mut data = Vec::with_capacity(total.min(lex.remaining() / 2 + 1));
    if one_frame_per_line(lex, channels) {
        read_rows(lex, frames, channels, &mut data)?;
    } else {
        read_stream(lex, frames, channels, total, &mut data)?;
    }
    if let Some(extra) = lex.next_token() {
        return Err(BvhError::ExtraData {
            line: extra.line,
            frames,
            channels,
        });
    }
    Ok((frame_time, data))
}

/// Reads the value after `key` in the forms `key: v`, `key:v`, `key : v` and `key v`.
fn keyed_value<'a>(lex: &mut Lexer<'a>, key: &str, expected: &str) -> Result<Token<'a>, BvhError> {
    let Some(tok) = lex.next_token() else {
        return Err(syntax(lex.line, format!("file ends before '{expected}'")));
    };
    let rest = tok
        .text
        .get(..key.len())
        .filter(|head| head.eq_ignore_ascii_case(key))
        .and_then(|_| tok.text.get(key.len()..));
    let missing_value = |lex: &Lexer<'_>| syntax(lex.line, format!("file ends after '{expected}'"));
    match rest {
        Some(":") => lex.next_token().ok_or_else(|| missing_value(lex)),
        Some("") => {
            if lex.peek().is_some_and(|t| t.text == ":") {
                lex.next_token();
            }
            lex.next_token().ok_or_else(|| missing_value(lex))
        }
        Some(glued) if glued.starts_with(':') => Ok(Token {
            text: &glued[1..],
            line: tok.line,
        }),
        _ => Err(syntax(
            tok.line,
            format!("expected '{expected}', found {}", tok.quoted()),
        )),
    }
}

/// The declared frame count, within [`MAX_FRAMES`].
fn frame_count(tok: Token<'_>) -> Result<usize, BvhError> {
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|c| c.is_ascii_digit());
    let too_many = || BvhError::TooManyFrames {
        line: tok.line,
        declared: show_name(tok.text),
        limit: MAX_FRAMES,
    };
    match tok.text.parse::<u64>() {
        Ok(n) => usize::try_from(n)
            .ok()
            .filter(|&n| n <= MAX_FRAMES)
            .ok_or_else(too_many),
        Err(_) if digits(tok.text) => Err(too_many()),
        Err(_) if tok.text.strip_prefix('-').is_some_and(digits) => {
            Err(BvhError::NegativeFrameCount {
                line: tok.line,
                count: tok.text.to_owned(),
            })
        }
        Err(_) => Err(syntax(
            tok.line,
            format!("frame count {} is not a whole number", tok.quoted()),
        )),
    }
}

/// Decides how frame rows are laid out from the first data lines. Rows are wrapped over
/// lines (read as a plain token stream) only when the first lines add up to exactly one
/// frame, or the first line holds a whole number of frames; otherwise each frame must be
/// on a line of its own, so a short or long row is reported at its line.
fn one_frame_per_line(lex: &Lexer<'_>, channels: usize) -> bool {
    let mut probe = lex.clone();
    let Some(first) = probe.next_token() else {
        return true;
    };
    let mut line = first.line;
    let mut on_line = 1;
    let mut total = 1;
    let mut lines = 1;
    loop {
        let next = probe.next_token();
        match next {
            Some(tok) if tok.line == line => {
                on_line += 1;
                total += 1;
                continue;
            }
            _ => {}
        }
        // Line `line` is complete.
        if lines == 1 && on_line >= channels {
            return on_line == channels || on_line % channels != 0;
        }
        if total >= channels {
            return total != channels;
        }
        let Some(tok) = next else {
            return true;
        };
        line = tok.line;
        on_line = 1;
        total += 1;
        lines += 1;
    }
}

/// Reads `frames` rows when every frame is on a line of its own.
fn read_rows(
    lex: &mut Lexer<'_>,
    frames: usize,
    channels: usize,
    data: &mut Vec<f64>,
) -> Result<(), BvhError> {
    let mut next = lex.clone().next_token();
    for frame in 0..frames {
        let Some(first) = next else {
            return Err(BvhError::Truncated {
                frames,
                channels,
                complete: frame,
            });
        };
        let line = first.line;
        let mut found = 0;
        loop {
            let before = lex.clone();
            let Some(tok) = lex.next_token() else {
                next = None;
                break;
            };
            if tok.line != line {
                // The next frame's first number: leave it unread.
                next = Some(tok);
                *lex = before;
                break;
            }
            if found < channels {
                data.push(number(tok)?);
            }
            found += 1;
        }
        if found != channels {
            if found < channels && next.is_none() {
                return Err(BvhError::Truncated {
                    frames,
                    channels,
                    complete: frame,
                });
            }
            return Err(BvhError::RowLength {
                line,
                frame,
                found,
                expected: channels,
            });
        }
    }
    Ok(())
}

/// Reads `total` numbers regardless of line breaks (rows wrapped by the exporter).
fn read_stream(
    lex: &mut Lexer<'_>,
    frames: usize,
    channels: usize,
    total: usize,
    data: &mut Vec<f64>,
) -> Result<(), BvhError> {
    while data.len() < total {
        let Some(tok) = lex.next_token() else {
            return Err(BvhError::Truncated {
                frames,
                channels,
                complete: data.len() / channels,
            });
        };
        data.push(number(tok)?);
    }
    Ok(())
}
