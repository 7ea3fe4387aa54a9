//! Following one face from frame to frame: pure logic over the detector's
//! answers, no ONNX Runtime, no GStreamer.
//!
//! Per frame, [`FaceTracker::track`] decides whether the detector runs, picks
//! the face to follow, smooths its crop and says how much of the relighting to
//! show (the fade weight), so the element moves its crop without jitter or lag
//! and fades, rather than pops, when the face goes or comes.
//!
//! - **When to detect**: every [`TrackerSettings::detect_interval`] frames, and at
//!   once when the tracking confidence falls under
//!   [`TrackerSettings::min_confidence`]. The confidence is how much the face's
//!   region still looks as it did at the last detection: the normalised
//!   cross-correlation of 16 × 16 luma thumbnails of the region (the face box
//!   widened by half) now and then. Each thumbnail is made zero-mean and divided
//!   by its standard deviation plus a floor, so a change of brightness (the
//!   monitor's light) does not count, and a featureless region (an empty wall)
//!   counts as unchanged rather than as noise.
//! - **Which face**: the [`TrackerSettings::face_index`]-th largest (0: the
//!   largest); the face already followed counts 1.2 times its size, so two faces
//!   of about one size do not swap on every detection.
//! - **Smoothing**: a One Euro filter (Casiez et al., CHI 2012) on the crop's
//!   centre and side: a low cutoff while the face is still (no jitter), rising
//!   with its speed (no lag).
//! - **Losing and finding**: a face the detector no longer finds is held for
//!   [`TrackerSettings::hold_frames`], then the fade weight goes 1 → 0 over
//!   [`TrackerSettings::fade_frames`]; a face found goes 0 → 1 over as many. A
//!   different face replacing a visible one first fades the old out, so the crop
//!   jumps only while nothing is shown.

use std::f32::consts::PI;

use super::{CropRule, FaceBox, Square, crop_from_face, sample_square};
use crate::frame::Frame;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerSettings {
    /// The detector runs at least every this many frames (1: every frame).
    pub detect_interval: u32,
    /// Which face to follow: 0 the largest, 1 the second largest, and so on.
    pub face_index: usize,
    /// Below this tracking confidence the detector runs at once.
    pub min_confidence: f32,
    /// Frames a lost face's crop is kept at full weight before fading.
    pub hold_frames: u32,
    /// Frames a fade out or in takes: half a second at 30 fps, so a relit face
    /// brightening by 10 levels comes in by under a level a frame.
    pub fade_frames: u32,
    /// One Euro filter: the cutoff (Hz) of a still face.
    pub min_cutoff: f32,
    /// One Euro filter: how fast the cutoff rises (Hz) per crop side a second of speed.
    pub beta: f32,
    /// From the face box to the square: the model's.
    pub crop: CropRule,
}

impl Default for TrackerSettings {
    fn default() -> Self {
        TrackerSettings {
            detect_interval: 5,
            face_index: 0,
            min_confidence: 0.9,
            hold_frames: 6,
            fade_frames: 15,
            min_cutoff: 0.5,
            beta: 8.0,
            crop: CropRule::TRAINING,
        }
    }
}

/// What one frame gets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tracked {
    /// The crop to relight, inside the frame. Before any face was found, the
    /// centred full-height square.
    pub square: Square,
    /// The square the crop rule gives round the followed face (smoothed),
    /// before it was moved inside the frame: where the face is in `square`.
    pub wanted: Square,
    /// How much of the relighting to show, in [0, 1]: 0 with no face.
    pub fade: f32,
    /// Whether the detector ran on this frame.
    pub detected: bool,
    /// The tracking confidence this frame, in [-1, 1] (0 before any detection).
    pub confidence: f32,
    /// The followed face as last detected.
    pub face: Option<FaceBox>,
}

/// Side of the thumbnails that measure the tracking confidence.
const THUMBNAIL: usize = 16;
/// Standard deviation (luma in [0, 1]) below which a thumbnail counts as featureless.
const FLAT: f32 = 0.02;
/// How much larger than its size the followed face counts when choosing a face.
const STICKY: f32 = 1.2;
/// The One Euro filter's cutoff (Hz) for the speed it estimates.
const SPEED_CUTOFF: f32 = 1.0;
/// Frame interval assumed when timestamps do not advance.
const DEFAULT_DT: f32 = 1.0 / 30.0;

pub struct FaceTracker {
    settings: TrackerSettings,
    /// The followed face as last detected; kept after it is lost, for its place.
    followed: Option<FaceBox>,
    /// Frames since a detection first missed the followed face; None while found.
    missing_for: Option<u32>,
    /// A different face waiting for the fade out to finish.
    pending: Option<FaceBox>,
    filter: Option<SquareFilter>,
    fade: f32,
    frames_since_detection: u32,
    reference: Option<Thumbnail>,
    last_time: Option<f64>,
}

impl FaceTracker {
    pub fn new(settings: TrackerSettings) -> FaceTracker {
        FaceTracker {
            settings,
            followed: None,
            missing_for: None,
            pending: None,
            filter: None,
            fade: 0.0,
            frames_since_detection: 0,
            reference: None,
            last_time: None,
        }
    }

    /// One frame at `time` seconds: runs `detect` on it if needed and returns its
    /// crop and fade weight. An error of `detect` is returned as it is, and the
    /// frame then does not count.
    pub fn track<E>(
        &mut self,
        frame: &Frame,
        time: f64,
        detect: impl FnOnce(&Frame) -> Result<Vec<FaceBox>, E>,
    ) -> Result<Tracked, E> {
        let confidence = self.reference.as_ref().map_or(0.0, |r| r.confidence(frame));
        let due = self.frames_since_detection + 1 >= self.settings.detect_interval;
        let detected = self.reference.is_none() || due || confidence < self.settings.min_confidence;
        let faces = if detected { Some(detect(frame)?) } else { None };

        if let Some(m) = &mut self.missing_for {
            *m += 1;
        }
        match faces {
            Some(faces) => {
                self.observe(&faces);
                let region = self
                    .followed
                    .map(thumbnail_region)
                    .or(self.reference.as_ref().map(|r| r.region))
                    .unwrap_or_else(|| Square::centred(frame.width, frame.height));
                self.reference = Some(Thumbnail::of(frame, region));
                self.frames_since_detection = 0;
            }
            None => self.frames_since_detection += 1,
        }

        let dt = match self.last_time {
            Some(last) if time > last => (time - last) as f32,
            _ => DEFAULT_DT,
        };
        let first_frame = self.last_time.is_none();
        self.last_time = Some(time);
        self.step_fade(first_frame);
        if self.fade == 0.0
            && let Some(face) = self.pending.take()
        {
            self.follow(face);
        }
        if let (Some(face), Some(filter)) = (self.followed, &mut self.filter) {
            filter.update(
                crop_from_face(&face, self.settings.crop),
                dt,
                &self.settings,
            );
        }
        let square = self
            .filter
            .as_ref()
            .map_or(Square::centred(frame.width, frame.height), |f| f.value());
        Ok(Tracked {
            square: square.clamped(frame.width, frame.height),
            wanted: square,
            fade: self.fade,
            detected,
            confidence,
            face: self.followed,
        })
    }

    /// Takes a detection's faces: the chosen one is followed, replaces the
    /// followed one, or is missing.
    fn observe(&mut self, faces: &[FaceBox]) {
        match (self.choose(faces), self.followed) {
            (Some(face), Some(followed)) if face.is_same_face(&followed) => {
                self.followed = Some(face);
                self.missing_for = None;
                self.pending = None;
            }
            (Some(face), _) if self.fade == 0.0 => self.follow(face),
            (Some(face), _) => {
                // Another face: fade the old one out now, then jump to it.
                self.pending = Some(face);
                self.missing_for = Some(self.settings.hold_frames);
            }
            (None, _) => {
                self.pending = None;
                if self.followed.is_some() && self.missing_for.is_none() {
                    self.missing_for = Some(0);
                }
            }
        }
    }

    /// The face the settings ask for, if there are enough faces.
    fn choose(&self, faces: &[FaceBox]) -> Option<FaceBox> {
        let weight = |f: &FaceBox| match self.followed {
            Some(followed) if f.is_same_face(&followed) => f.area() * STICKY,
            _ => f.area(),
        };
        let mut ranked = faces.to_vec();
        ranked.sort_by(|a, b| weight(b).total_cmp(&weight(a)));
        ranked.get(self.settings.face_index).copied()
    }

    /// Follows `face` from here on, its crop where it is: only while nothing is shown.
    fn follow(&mut self, face: FaceBox) {
        self.followed = Some(face);
        self.missing_for = None;
        self.pending = None;
        self.filter = Some(SquareFilter::new(crop_from_face(&face, self.settings.crop)));
    }

    /// Moves the fade weight one frame towards 1 while a face is followed and not
    /// lost beyond the hold, else towards 0. A stream's first frame has nothing to
    /// pop from: a face there is shown at once.
    fn step_fade(&mut self, first_frame: bool) {
        let shown = self.followed.is_some()
            && self
                .missing_for
                .is_none_or(|m| m < self.settings.hold_frames);
        let target = if shown { 1.0 } else { 0.0 };
        let step = if first_frame {
            1.0
        } else {
            1.0 / self.settings.fade_frames.max(1) as f32
        };
        self.fade = if target > self.fade {
            (self.fade + step).min(target)
        } else {
            (self.fade - step).max(target)
        };
        // Steps of 1 / fade_frames do not add up to exactly 1 in floating point
        // for every count (15 falls short): land on the target.
        if (self.fade - target).abs() < step / 2.0 {
            self.fade = target;
        }
    }
}

/// Where the tracking confidence looks: the face box widened by half.
fn thumbnail_region(face: FaceBox) -> Square {
    Square {
        cx: face.cx,
        cy: face.cy,
        side: 1.5 * face.width.max(face.height),
    }
}

/// A region's luma at [`THUMBNAIL`]², zero-mean and scaled to unit deviation (a
/// featureless one less).
struct Thumbnail {
    region: Square,
    pixels: Vec<f32>,
}

impl Thumbnail {
    fn of(frame: &Frame, region: Square) -> Thumbnail {
        let luma: Vec<f32> = sample_square(frame, region, THUMBNAIL)
            .iter()
            .map(|p| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2])
            .collect();
        let n = luma.len() as f32;
        let mean = luma.iter().sum::<f32>() / n;
        let std = (luma.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / n).sqrt();
        Thumbnail {
            region,
            pixels: luma.iter().map(|v| (v - mean) / (std + FLAT)).collect(),
        }
    }

    /// The tracking confidence: how alike the same region of `frame` is, 1 for
    /// the same picture. For thumbnails of unit deviation this is their
    /// normalised cross-correlation, `1 − mean((a − b)²) / 2`.
    fn confidence(&self, frame: &Frame) -> f32 {
        let now = Thumbnail::of(frame, self.region);
        let n = self.pixels.len() as f32;
        let squared: f32 = self
            .pixels
            .iter()
            .zip(&now.pixels)
            .map(|(a, b)| (a - b).powi(2))
            .sum();
        1.0 - squared / n / 2.0
    }
}

/// One Euro filters on a square's centre and side.
struct SquareFilter {
    channels: [OneEuro; 3],
}

impl SquareFilter {
    fn new(start: Square) -> SquareFilter {
        SquareFilter {
            channels: [start.cx, start.cy, start.side].map(OneEuro::new),
        }
    }

    fn update(&mut self, target: Square, dt: f32, settings: &TrackerSettings) {
        // Speeds in crop sides a second, so the settings hold at any frame size.
        let scale = self.channels[2].value.max(1.0);
        for (c, x) in self
            .channels
            .iter_mut()
            .zip([target.cx, target.cy, target.side])
        {
            c.update(x, dt, scale, settings);
        }
    }

    fn value(&self) -> Square {
        let [cx, cy, side] = self.channels.each_ref().map(|c| c.value);
        Square { cx, cy, side }
    }
}

/// The One Euro filter: a low-pass whose cutoff rises with the signal's speed.
struct OneEuro {
    value: f32,
    /// The low-passed speed, units a second.
    speed: f32,
}

impl OneEuro {
    fn new(value: f32) -> OneEuro {
        OneEuro { value, speed: 0.0 }
    }

    fn update(&mut self, x: f32, dt: f32, scale: f32, settings: &TrackerSettings) {
        // The smoothing factor of a first-order low-pass at `cutoff` Hz.
        let alpha = |cutoff: f32| 1.0 / (1.0 + 1.0 / (2.0 * PI * cutoff * dt));
        self.speed += alpha(SPEED_CUTOFF) * ((x - self.value) / dt - self.speed);
        let cutoff = settings.min_cutoff + settings.beta * self.speed.abs() / scale;
        self.value += alpha(cutoff) * (x - self.value);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::face::face;

    /// A grey 320x240 frame: the tracker's thumbnails see nothing change, so
    /// only the interval decides when the (scripted) detector runs.
    fn grey() -> Vec<u8> {
        vec![128; 320 * 240 * 3]
    }

    /// Runs `frames` frames at 30 fps, the detector answering `faces(i)`; returns
    /// what each frame got.
    fn run(
        tracker: &mut FaceTracker,
        frames: std::ops::Range<usize>,
        faces: impl Fn(usize) -> Vec<FaceBox>,
    ) -> Vec<Tracked> {
        let data = grey();
        let frame = Frame::packed_rgb(&data, 320, 240);
        frames
            .map(|i| {
                tracker
                    .track(&frame, i as f64 / 30.0, |_| Ok::<_, ()>(faces(i)))
                    .unwrap()
            })
            .collect()
    }

    #[test]
    fn the_detector_runs_every_interval_on_a_still_picture() {
        let mut t = FaceTracker::new(TrackerSettings::default());
        let out = run(&mut t, 0..12, |_| vec![face(160.0, 100.0, 50.0)]);
        let ran: Vec<usize> = (0..12).filter(|&i| out[i].detected).collect();
        assert_eq!(ran, vec![0, 5, 10]);
    }

    #[test]
    fn a_failed_detection_leaves_the_tracker_as_it_was() {
        let data = grey();
        let frame = Frame::packed_rgb(&data, 320, 240);
        let mut t = FaceTracker::new(TrackerSettings::default());
        assert!(t.track(&frame, 0.0, |_| Err("inference failed")).is_err());
        let out = t
            .track(&frame, 1.0 / 30.0, |_| {
                Ok::<_, &str>(vec![face(160.0, 100.0, 50.0)])
            })
            .unwrap();
        assert!(out.detected && out.face.is_some());
    }

    #[test]
    fn a_face_fades_in_and_after_the_hold_fades_out() {
        let s = TrackerSettings {
            detect_interval: 1,
            ..TrackerSettings::default()
        };
        let mut t = FaceTracker::new(s);
        // Nobody for 3 frames, a face for 20, nobody again.
        let out = run(&mut t, 0..60, |i| {
            if (3..23).contains(&i) {
                vec![face(160.0, 100.0, 50.0)]
            } else {
                vec![]
            }
        });
        let fades: Vec<f32> = out.iter().map(|o| o.fade).collect();
        assert!(fades[..3].iter().all(|&f| f == 0.0), "{fades:?}");
        // In over fade_frames, from the face's first frame.
        let step = 1.0 / s.fade_frames as f32;
        for i in 0..s.fade_frames as usize {
            assert!(
                (fades[3 + i] - step * (i + 1) as f32).abs() < 1e-5,
                "{fades:?}"
            );
        }
        // Held, then out over fade_frames; the crop stays where the face was.
        let gone = 23 + s.hold_frames as usize;
        assert!(fades[23..gone].iter().all(|&f| f == 1.0), "{fades:?}");
        assert!(fades[gone] < 1.0 && fades[gone + s.fade_frames as usize - 1] == 0.0);
        assert_eq!(out[59].square, out[22].square);
        // A stream that starts on a face shows it at once: nothing to pop from.
        let mut fresh = FaceTracker::new(s);
        let first = run(&mut fresh, 0..1, |_| vec![face(160.0, 100.0, 50.0)]);
        assert_eq!(first[0].fade, 1.0);
    }

    #[test]
    fn the_largest_face_is_followed_unless_the_setting_picks_another() {
        let two = |_| vec![face(80.0, 100.0, 40.0), face(240.0, 100.0, 60.0)];
        let mut largest = FaceTracker::new(TrackerSettings::default());
        let out = run(&mut largest, 0..3, two);
        assert_eq!(out[2].face.unwrap().cx, 240.0);
        let mut second = FaceTracker::new(TrackerSettings {
            face_index: 1,
            ..TrackerSettings::default()
        });
        let out = run(&mut second, 0..3, two);
        assert_eq!(out[2].face.unwrap().cx, 80.0);
        // There is no third face.
        let mut third = FaceTracker::new(TrackerSettings {
            face_index: 2,
            ..TrackerSettings::default()
        });
        assert!(run(&mut third, 0..3, two).iter().all(|o| o.fade == 0.0));
    }

    #[test]
    fn another_face_is_faded_to_not_jumped_to() {
        let s = TrackerSettings {
            detect_interval: 1,
            ..TrackerSettings::default()
        };
        let mut t = FaceTracker::new(s);
        let out = run(&mut t, 0..60, |i| {
            vec![if i < 20 {
                face(80.0, 100.0, 40.0)
            } else {
                face(240.0, 100.0, 40.0)
            }]
        });
        // The crop does not move while anything is shown, until the old face faded out.
        for w in out.windows(2) {
            if w[1].square.cx != w[0].square.cx && w[0].fade > 0.0 && w[1].fade > 0.0 {
                assert!(
                    (w[1].square.cx - w[0].square.cx).abs() < 1.0,
                    "jumped while shown: {w:?}"
                );
            }
        }
        assert!((out[59].square.cx - 240.0).abs() < 1.0 && out[59].fade == 1.0);
    }

    #[test]
    fn a_still_face_keeps_its_crop_and_a_moving_one_is_followed() {
        let mut t = FaceTracker::new(TrackerSettings {
            detect_interval: 1,
            ..TrackerSettings::default()
        });
        // Still, with a pixel of detection noise: the crop moves far less.
        let still = run(&mut t, 0..60, |i| {
            vec![face(
                160.0 + if i % 2 == 0 { 1.0 } else { -1.0 },
                100.0,
                40.0,
            )]
        });
        let xs: Vec<f32> = still[30..].iter().map(|o| o.square.cx).collect();
        let spread = xs.iter().cloned().fold(f32::MIN, f32::max)
            - xs.iter().cloned().fold(f32::MAX, f32::min);
        assert!(spread < 0.3, "still face: the crop moves {spread} px");
        // Moving at 3 px a frame: followed within a few pixels.
        let moving = run(&mut t, 60..90, |i| {
            vec![face(160.0 + 3.0 * (i - 59) as f32, 100.0, 40.0)]
        });
        let lag = 160.0 + 3.0 * 30.0 - moving[29].square.cx;
        assert!(lag.abs() < 12.0, "moving face: {lag} px behind");
    }
}
