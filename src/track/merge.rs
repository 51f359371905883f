//! Each frame's answer among the passes' answers ([`TrackOptions::two_way`],
//! [`TrackOptions::middle_pass`]): the sequence over a block of frames whose
//! summed cost, plus a penalty for each move between neighbouring frames, is the
//! least.
//!
//! The passes start from different frames and go wrong in different places, so a
//! frame has several answers (three by default: the first pass's, the second's and
//! the middle pass's; more with more middle passes). Taking the cheapest answer
//! frame by frame lets a wrong pose that happens to cost a little less on one frame
//! break into a track that is right on its neighbours; the answers the passes swap
//! are often far apart (the heading turned by more than 40°). Charging each step
//! from one frame's answer to the next's for the distance between the two poses
//! keeps a pass's track where it is only a little dearer, and still moves to
//! another pass's track where that is cheaper over a run of frames. The choice is a
//! shortest path through the frames' answers (the Viterbi algorithm): with three
//! answers a frame, nine distances a frame, and no evaluation of the objective.
//!
//! [`TrackOptions::two_way`]: super::tracker::TrackOptions::two_way
//! [`TrackOptions::middle_pass`]: super::tracker::TrackOptions::middle_pass

use super::tracker::TrackedFrame;
use crate::body::camera::Camera;
use crate::body::params::{ix, Pose, MOTION, MOTION_COUNT};
use crate::body::skeleton::Joint;
use crate::body::Body;

/// How far apart two poses are: the sum over the 30 values of each difference in
/// its length scale (the heading's taken the short way round).
pub fn distance(a: &Pose, b: &Pose) -> f64 {
    (0..MOTION_COUNT)
        .map(|k| {
            let mut d = (a[k] - b[k]).abs();
            if k == ix::ROOT_RY {
                d = d.rem_euclid(360.0);
                d = d.min(360.0 - d);
            }
            d / MOTION[k].scale
        })
        .sum()
}

/// How far two passes' answers for the same frames part: the mean, over the frames
/// where both found a person, of the share of the joints whose image positions lie
/// more than a tenth of the body's image height apart (the height spanned by the
/// joints of `a`'s pose; a joint behind the camera in either counts as apart). 0
/// when no frame has a person in both.
pub fn apart(body: &Body, camera: &Camera, a: &[TrackedFrame], b: &[TrackedFrame]) -> f64 {
    let image = |pose: &Pose| {
        let posed = body.posed(pose);
        Joint::ALL.map(|j| camera.project(&posed.joint(j)))
    };
    let mut shares = Vec::new();
    for (x, y) in a.iter().zip(b).filter(|(x, y)| x.person && y.person) {
        let (p, q) = (image(&x.pose), image(&y.pose));
        let (lo, hi) = p
            .iter()
            .flatten()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v[1]), hi.max(v[1]))
            });
        let near = 0.1 * (hi - lo);
        let far = p.iter().zip(&q).filter(|(u, v)| match (u, v) {
            (Some(u), Some(v)) => (u[0] - v[0]).hypot(u[1] - v[1]) > near,
            _ => true,
        });
        shares.push(far.count() as f64 / Joint::ALL.len() as f64);
    }
    match shares.len() {
        0 => 0.0,
        n => shares.iter().sum::<f64>() / n as f64,
    }
}

/// An answer the choice may take: a person found, at a finite cost.
fn usable(f: &TrackedFrame) -> Option<f64> {
    f.cost.filter(|c| f.person && c.is_finite())
}

/// For each frame of a block (in order; each with its answers, the first pass's
/// first), which answer it takes. Over each run of frames whose answers are usable,
/// the sequence with the least summed cost plus `penalty` times the [`distance`]
/// between each frame's pose and the next's, the penalty taken in units of the
/// median over the block of each frame's cheapest cost. A frame with no usable
/// answer takes its first and breaks the run. Ties go to the earlier answer, so a
/// `penalty` of 0 takes each frame's cheapest answer, the first where it is as
/// cheap as any.
pub fn choose(answers: &[Vec<TrackedFrame>], penalty: f64) -> Vec<usize> {
    let mut cheapest: Vec<f64> = answers
        .iter()
        .filter_map(|a| a.iter().filter_map(usable).min_by(f64::total_cmp))
        .collect();
    cheapest.sort_by(f64::total_cmp);
    let unit = cheapest.get(cheapest.len() / 2).map_or(0.0, |c| c.abs());
    let per_unit = penalty * unit;
    let mut chosen = vec![0; answers.len()];
    let mut i = 0;
    while i < answers.len() {
        let start = i;
        while i < answers.len() && answers[i].iter().any(|f| usable(f).is_some()) {
            i += 1;
        }
        if i == start {
            i += 1;
            continue;
        }
        choose_run(&answers[start..i], per_unit, &mut chosen[start..i]);
    }
    chosen
}

/// The least of `(total, answer)` pairs by total, the earliest among equals;
/// (∞, 0) for none.
fn least(pairs: impl Iterator<Item = (f64, usize)>) -> (f64, usize) {
    pairs.fold((f64::INFINITY, 0), |m, x| if x.0 < m.0 { x } else { m })
}

/// [`choose`] over a run of frames, each with a usable answer.
fn choose_run(run: &[Vec<TrackedFrame>], per_unit: f64, chosen: &mut [usize]) {
    // For each frame and answer: the least total up to it, and the answer before it
    // on that path.
    let mut best: Vec<Vec<(f64, usize)>> = Vec::with_capacity(run.len());
    for (t, answers) in run.iter().enumerate() {
        let row = answers
            .iter()
            .map(|f| {
                let Some(cost) = usable(f) else {
                    return (f64::INFINITY, 0);
                };
                if t == 0 {
                    return (cost, 0);
                }
                let (total, from) =
                    least(run[t - 1].iter().enumerate().map(|(a, p)| {
                        (best[t - 1][a].0 + per_unit * distance(&p.pose, &f.pose), a)
                    }));
                (total + cost, from)
            })
            .collect();
        best.push(row);
    }
    let last = best.len() - 1;
    let mut at = least(best[last].iter().enumerate().map(|(a, x)| (x.0, a))).1;
    for t in (0..=last).rev() {
        chosen[t] = at;
        at = best[t][at].1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An answer for frame `index` with every value `x` and this cost.
    fn answer(index: usize, x: f64, cost: f64) -> TrackedFrame {
        TrackedFrame {
            index,
            person: true,
            pose: [x; MOTION_COUNT],
            cost: Some(cost),
            iou: Some(0.9),
            keyframe: false,
        }
    }

    /// Two tracks over `costs.len()` frames: the first pass's at 0, another at 10.
    fn two_tracks(costs: &[(f64, f64)]) -> Vec<Vec<TrackedFrame>> {
        costs
            .iter()
            .enumerate()
            .map(|(i, &(a, b))| vec![answer(i, 0.0, a), answer(i, 10.0, b)])
            .collect()
    }

    #[test]
    fn passes_part_where_their_joints_lie_apart_in_the_image() {
        use crate::body::params::{rest_pose, STANDARD_SHAPE};
        let body = Body::new(&STANDARD_SHAPE);
        let cam = Camera::new(320, 240, 55.0);
        let mut pose = rest_pose();
        pose[ix::ROOT_TY] -= 100.0;
        pose[ix::ROOT_TZ] = -400.0;
        let track = |pose: Pose| -> Vec<TrackedFrame> {
            (0..4)
                .map(|i| TrackedFrame {
                    pose,
                    ..answer(i, 0.0, 1.0)
                })
                .collect()
        };
        let a = track(pose);
        assert_eq!(apart(&body, &cam, &a, &a), 0.0);
        // The left arm raised and bent: some of the joints, far from most, move by
        // more than a tenth of the body's height.
        let mut raised = pose;
        raised[ix::L_SHOULDER + 1] = 90.0;
        raised[ix::L_ELBOW] = 90.0;
        let b = track(raised);
        let share = apart(&body, &cam, &a, &b);
        assert!(share > 0.0 && share < 0.25, "{share}");
        // Frames where either has no person do not count; with none left, 0.
        let mut c = b.clone();
        c[0].person = false;
        c[1] = TrackedFrame { pose, ..c[1] };
        c[1].person = false;
        assert_eq!(apart(&body, &cam, &a, &c), share);
        let none: Vec<TrackedFrame> = c
            .iter()
            .map(|f| TrackedFrame {
                person: false,
                ..*f
            })
            .collect();
        assert_eq!(apart(&body, &cam, &a, &none), 0.0);
    }

    #[test]
    fn the_distance_weighs_each_value_by_its_length_scale() {
        let a = [0.0; MOTION_COUNT];
        let mut b = a;
        b[ix::ROOT_TX] = MOTION[ix::ROOT_TX].scale;
        b[ix::ROOT_RX] = -2.0 * MOTION[ix::ROOT_RX].scale;
        assert!((distance(&a, &b) - 3.0).abs() < 1e-12);
        assert_eq!(distance(&a, &b), distance(&b, &a));
        // The heading the short way round: 350° from 0° is 10° away, 360° none.
        let mut c = a;
        c[ix::ROOT_RY] = 350.0;
        assert!((distance(&a, &c) - 10.0 / MOTION[ix::ROOT_RY].scale).abs() < 1e-12);
        c[ix::ROOT_RY] = -360.0;
        assert_eq!(distance(&a, &c), 0.0);
    }

    #[test]
    fn without_a_penalty_each_frame_takes_its_cheapest_answer() {
        let answers = two_tracks(&[(10.0, 9.0), (10.0, 11.0), (10.0, 10.0), (-5.0, -6.0)]);
        assert_eq!(
            choose(&answers, 0.0),
            vec![1, 0, 0, 1],
            "a tie keeps the first"
        );
    }

    #[test]
    fn a_lone_cheaper_frame_does_not_break_into_a_track() {
        // One frame where the other track is 5 cheaper: leaving it and coming back
        // costs two moves between the tracks, each 0.01 × the median cost 100 ×
        // their distance.
        let move_cost = 0.01 * 100.0 * distance(&[0.0; MOTION_COUNT], &[10.0; MOTION_COUNT]);
        assert!(2.0 * move_cost > 5.0);
        let mut costs = vec![(100.0, 120.0); 9];
        costs[4] = (100.0, 95.0);
        let answers = two_tracks(&costs);
        let mut expected = vec![0; 9];
        assert_eq!(choose(&answers, 0.01), expected);
        expected[4] = 1;
        assert_eq!(choose(&answers, 0.0), expected);
    }

    #[test]
    fn a_run_of_cheaper_frames_is_taken_whole() {
        // The other track is cheaper from frame 3 on, over the run by 60: more than
        // one move costs (0.01 × the median cost 90 × the tracks' distance).
        let move_cost = 0.01 * 90.0 * distance(&[0.0; MOTION_COUNT], &[10.0; MOTION_COUNT]);
        assert!(move_cost < 60.0);
        let costs: Vec<(f64, f64)> = (0..9)
            .map(|i| if i < 3 { (80.0, 200.0) } else { (100.0, 90.0) })
            .collect();
        let answers = two_tracks(&costs);
        assert_eq!(choose(&answers, 0.01), vec![0, 0, 0, 1, 1, 1, 1, 1, 1]);
        // A penalty too dear for the gain keeps the first track.
        assert_eq!(choose(&answers, 1.0), vec![0; 9]);
    }

    #[test]
    fn frames_without_a_usable_answer_break_the_runs() {
        let mut answers = two_tracks(&[(10.0, 5.0), (10.0, 5.0), (10.0, 5.0)]);
        for f in &mut answers[1] {
            f.person = false;
            f.cost = None;
        }
        // A frame whose only usable answer is its second one takes it.
        answers[2][0].cost = Some(f64::INFINITY);
        assert_eq!(choose(&answers, 10.0), vec![1, 0, 1]);
        // A frame with the first pass's answer alone.
        let lone = vec![vec![answer(0, 0.0, 3.0)]];
        assert_eq!(choose(&lone, 0.01), vec![0]);
        assert!(choose(&[], 0.01).is_empty());
    }
}
