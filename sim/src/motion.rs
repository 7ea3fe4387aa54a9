//! Pose, expression and presence over time.
//!
//! People watching videos hold a pose for a while, then shift; they talk,
//! smile and blink. A trajectory is a list of pose keyframes (some of them
//! holds) eased into one another, with talking spells, smiles and blinks on
//! top. Everything is a pure function of the seed and the time.

use std::f64::consts::TAU;

use serde::{Deserialize, Serialize};

use crate::math::{Vec3, lerp, smoothstep};
use crate::rng::Rng;
use crate::subject::{Expression, Pose, State};

/// How far poses range, in degrees and metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    pub yaw_deg: f32,
    pub pitch_deg: f32,
    pub roll_deg: f32,
    pub shift: Vec3,
}

impl Range {
    /// The paper's free capture: yaw ±30°, pitch ±15°, some roll and translation.
    pub const CAPTURE: Range = Range {
        yaw_deg: 30.0,
        pitch_deg: 15.0,
        roll_deg: 8.0,
        shift: Vec3::new(0.04, 0.03, 0.08),
    };
    /// A person on a call: smaller movements.
    pub const CALL: Range = Range {
        yaw_deg: 18.0,
        pitch_deg: 8.0,
        roll_deg: 5.0,
        shift: Vec3::new(0.03, 0.02, 0.04),
    };
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Key {
    t: f64,
    yaw: f32,
    pitch: f32,
    roll: f32,
    shift: Vec3,
    body: Vec3,
    smile: f32,
}

/// A place on a walk about the room: at `t` seconds the person's head is turned
/// by `yaw_deg` and their whole body has moved by `body` metres (x right, y down,
/// z away from the camera) from the desk.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Waypoint {
    pub t: f64,
    pub yaw_deg: f32,
    pub body: [f32; 3],
}

/// A person's motion over a stretch of time.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    keys: Vec<Key>,
    /// Start times of blinks.
    blinks: Vec<f64>,
    /// Talking spells: (start, end, syllable rate in Hz).
    talking: Vec<(f64, f64, f64)>,
    /// Times when the person is out of the frame: (leave, return).
    absent: Vec<(f64, f64)>,
}

const BLINK_SECONDS: f64 = 0.16;

impl Trajectory {
    /// A random trajectory of `duration` seconds; `hold` is the chance that a
    /// keyframe keeps the previous pose.
    pub fn random(seed: u64, domain: &str, duration: f64, range: Range, hold: f32) -> Trajectory {
        let mut r = Rng::stream(seed, domain);
        let mut keys = Vec::new();
        let mut t = 0.0;
        let random_key = |r: &mut Rng, t: f64| Key {
            t,
            yaw: r.range(-range.yaw_deg, range.yaw_deg),
            pitch: r.range(-range.pitch_deg, range.pitch_deg),
            roll: r.range(-range.roll_deg, range.roll_deg),
            shift: Vec3::new(
                r.range(-range.shift.x, range.shift.x),
                r.range(-range.shift.y, range.shift.y),
                r.range(-range.shift.z, range.shift.z),
            ),
            body: Vec3::ZERO,
            smile: if r.chance(0.3) {
                r.range(0.3, 1.0)
            } else {
                0.0
            },
        };
        while t <= duration + 3.0 {
            let key = match keys.last() {
                Some(prev) if r.chance(hold) => Key { t, ..*prev },
                _ => random_key(&mut r, t),
            };
            keys.push(key);
            t += r.range(0.6, 2.5) as f64;
        }
        let mut blinks = Vec::new();
        let mut tb = r.range(0.5, 3.0) as f64;
        while tb < duration {
            blinks.push(tb);
            tb += r.range(2.0, 6.0) as f64;
        }
        let mut talking = Vec::new();
        let mut tt = r.range(0.0, 4.0) as f64;
        while tt < duration {
            let len = r.range(0.8, 3.5) as f64;
            talking.push((tt, tt + len, r.range(3.0, 5.0) as f64));
            tt += len + r.range(1.0, 6.0) as f64;
        }
        Trajectory {
            keys,
            blinks,
            talking,
            absent: Vec::new(),
        }
    }

    /// The same motion, with the person out of the frame from `leave` to `back`.
    pub fn with_absence(mut self, leave: f64, back: f64) -> Trajectory {
        self.absent.push((leave, back));
        self
    }

    /// The same blinks and talking, with the person walking through `path`
    /// instead of sitting: eased from waypoint to waypoint, holding the first
    /// before it and the last after it.
    pub fn along(mut self, path: &[Waypoint]) -> Trajectory {
        assert!(path.len() >= 2, "a path has at least two waypoints");
        self.keys = path
            .iter()
            .map(|w| Key {
                t: w.t,
                yaw: w.yaw_deg,
                pitch: 0.0,
                roll: 0.0,
                shift: Vec3::ZERO,
                body: Vec3::new(w.body[0], w.body[1], w.body[2]),
                smile: 0.0,
            })
            .collect();
        self
    }

    /// The person's state at time `t` seconds.
    pub fn state(&self, t: f64) -> State {
        let present = !self.absent.iter().any(|&(a, b)| t >= a && t < b);
        let i = self
            .keys
            .partition_point(|k| k.t <= t)
            .clamp(1, self.keys.len() - 1);
        let (a, b) = (&self.keys[i - 1], &self.keys[i]);
        let w = smoothstep(0.0, 1.0, ((t - a.t) / (b.t - a.t)) as f32);
        let pose = Pose {
            yaw: lerp(a.yaw, b.yaw, w).to_radians(),
            pitch: lerp(a.pitch, b.pitch, w).to_radians(),
            roll: lerp(a.roll, b.roll, w).to_radians(),
            translation: a.shift.lerp(b.shift, w),
            body: a.body.lerp(b.body, w),
            present,
        };
        let blink = self
            .blinks
            .iter()
            .map(|&s| {
                let x = (t - s) / BLINK_SECONDS;
                if (0.0..1.0).contains(&x) {
                    1.0 - (2.0 * x - 1.0).abs()
                } else {
                    0.0
                }
            })
            .fold(0.0f64, f64::max) as f32;
        let mouth_open = self
            .talking
            .iter()
            .filter(|&&(s, e, _)| t >= s && t < e)
            .map(|&(s, e, rate)| {
                let envelope =
                    smoothstep(0.0, 0.2, (t - s) as f32) * smoothstep(0.0, 0.2, (e - t) as f32);
                let syllable = 0.5 - 0.5 * (TAU * rate * (t - s)).cos();
                envelope * syllable as f32 * 0.8
            })
            .fold(0.0f32, f32::max);
        State {
            pose,
            expression: Expression {
                mouth_open,
                smile: lerp(a.smile, b.smile, w),
                blink,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stays_in_range_and_is_deterministic() {
        let a = Trajectory::random(5, "train", 60.0, Range::CAPTURE, 0.5);
        assert_eq!(a, Trajectory::random(5, "train", 60.0, Range::CAPTURE, 0.5));
        for i in 0..600 {
            let s = a.state(i as f64 * 0.1);
            assert!(s.pose.yaw.to_degrees().abs() <= 30.0 + 1e-3);
            assert!(s.pose.pitch.to_degrees().abs() <= 15.0 + 1e-3);
            assert!((0.0..=1.0).contains(&s.expression.blink));
            assert!((0.0..=1.0).contains(&s.expression.mouth_open));
        }
    }

    #[test]
    fn absence_hides_the_person() {
        let a = Trajectory::random(5, "rec", 10.0, Range::CALL, 0.5).with_absence(2.0, 4.0);
        assert!(a.state(1.9).pose.present);
        assert!(!a.state(3.0).pose.present);
        assert!(a.state(4.1).pose.present);
    }

    #[test]
    fn a_walk_passes_its_waypoints_and_holds_the_last() {
        let at = |t: f64, x: f32, yaw_deg: f32| Waypoint {
            t,
            yaw_deg,
            body: [x, 0.0, 0.1],
        };
        let a = Trajectory::random(5, "rec", 4.0, Range::CALL, 0.5)
            .along(&[at(0.0, -0.2, 0.0), at(2.0, 0.2, 10.0)]);
        assert_eq!(a.state(0.0).pose.body, Vec3::new(-0.2, 0.0, 0.1));
        assert!(a.state(1.0).pose.body.x.abs() < 1e-6, "halfway");
        assert_eq!(a.state(3.0).pose.body, Vec3::new(0.2, 0.0, 0.1));
        assert!((a.state(3.0).pose.yaw.to_degrees() - 10.0).abs() < 1e-4);
        // Walking, not shifting in the chair.
        assert_eq!(a.state(1.0).pose.translation, Vec3::ZERO);
    }

    #[test]
    fn motion_is_continuous() {
        let a = Trajectory::random(9, "train", 30.0, Range::CAPTURE, 0.3);
        for i in 0..900 {
            let (s0, s1) = (a.state(i as f64 / 30.0), a.state((i + 1) as f64 / 30.0));
            assert!((s0.pose.yaw - s1.pose.yaw).abs().to_degrees() < 6.0);
        }
    }
}
