//! What the user is told while recording, measured from the data: how many
//! camera frames are usable for training, how many of them can pair with
//! another (the same pose under different screen light, which is what the
//! trainer learns from), how much of the face's light comes
//! from the monitor rather than the room, whether the face is in view, whether
//! pose and expression vary, and which head poses the session has covered.
//! GStreamer-free: the capture feeds it camera and screen observations in
//! running time, in any interleaving of the two streams.

use std::collections::VecDeque;
use std::sync::Arc;

use gstlsydrelight::light::{LIGHT_COLS, LIGHT_ROWS, srgb_byte_to_linear};

use serde::Serialize;

/// Smallest face worth training on, in pixels of face-box height: below it the
/// network's 256-pixel crop (2.9 face heights) is upsampled more than about 1.8x.
pub const MIN_FACE_HEIGHT: f32 = 48.0;
/// Without a face for this long, the user is told.
pub const FACE_LOST_SECONDS: f64 = 1.0;
/// The monitor's share of the face's light is measured over this much recent time.
pub const SHARE_WINDOW_SECONDS: f64 = 10.0;
/// The share is judged once this much of the window is filled.
pub const MIN_SHARE_SECONDS: f64 = 3.0;
/// Below this share the room light overpowers the monitor.
pub const MIN_MONITOR_SHARE: f64 = 0.4;
/// Screen luminance must vary at least this much (standard deviation, linear)
/// over the window for the share to be measurable.
pub const MIN_SCREEN_VARIATION: f64 = 0.01;
/// Pose and expression variation is judged over this much recent time.
pub const MOTION_WINDOW_SECONDS: f64 = 4.0;
/// Below this keypoint spread (summed standard deviations of face-relative
/// keypoint positions) pose and expression count as barely varying.
pub const MIN_KEYPOINT_SPREAD: f64 = 0.06;
/// Two frames pair when their keypoints (eyes, nose tip, mouth) lie within
/// this share of the eye distance of each other, on average, in the frame's
/// pixels. The trainer pairs by 68 keypoints at 0.02; the detector's four are
/// coarser, so this is an estimate, calibrated on simulated captures (README,
/// "Your own light stage"). Where the face is counts: compared relative to the
/// eyes instead, a naturally moving head that the trainer paired nowhere
/// counted 61 % of its frames. On small faces (eyes under 30 px apart) the
/// detector's keypoints shift with the light on the face, and a full-screen
/// black-to-white flip can hide real pairs.
pub const PAIR_KEYPOINT_DISTANCE: f32 = 0.03;
/// ... and their screen lights differ by at least this mean absolute difference
/// (linear light), the trainer's rule.
pub const PAIR_LIGHT_DIFFERENCE: f32 = 0.03;
/// The share of usable frames that pair is judged over this much recent time ...
pub const PAIRING_WINDOW_SECONDS: f64 = 20.0;
/// ... and below this share the user is told how to get more.
pub const MIN_PAIRABLE_SHARE: f64 = 0.1;
/// The light is compared on the contract's grid averaged over blocks of 2 x 2
/// cells: a quarter of the memory and time, and a block's difference is at
/// most its cells' mean difference, so pairs are never overcounted.
const PAIR_LIGHT_LEN: usize = 3 * (LIGHT_ROWS / 2) * (LIGHT_COLS / 2);
/// A warning that still holds is repeated after this long.
pub const REPEAT_SECONDS: f64 = 30.0;
/// Head-turn bins (nose offset from the eyes' midpoint, in face widths) and
/// head-tilt bins (the nose's place between eyes and mouth, 0 at the eyes).
const YAW_EDGES: [f64; 4] = [-0.12, -0.04, 0.04, 0.12];
const PITCH_EDGES: [f64; 2] = [0.45, 0.6];
pub const POSE_BINS: usize = (YAW_EDGES.len() + 1) * (PITCH_EDGES.len() + 1);

/// The face the detector found in a camera frame, in the frame's pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Face {
    pub width: f32,
    pub height: f32,
    /// Right eye, left eye, nose tip, mouth centre (BlazeFace's first four keypoints).
    pub eyes: [[f32; 2]; 2],
    pub nose: [f32; 2],
    pub mouth: [f32; 2],
    /// Mean linear luminance of the face's inner region.
    pub luminance: f64,
}

impl Face {
    /// Head turn and tilt proxies and mouth opening, in face sizes.
    fn descriptor(&self) -> [f64; 3] {
        let mid = [
            (self.eyes[0][0] + self.eyes[1][0]) / 2.0,
            (self.eyes[0][1] + self.eyes[1][1]) / 2.0,
        ];
        let eyes_to_mouth = (self.mouth[1] - mid[1]).max(1.0);
        [
            ((self.nose[0] - mid[0]) / self.width.max(1.0)) as f64,
            ((self.nose[1] - mid[1]) / eyes_to_mouth) as f64,
            ((self.mouth[1] - self.nose[1]) / self.height.max(1.0)) as f64,
        ]
    }

    fn eye_distance(&self) -> f32 {
        let [r, l] = self.eyes;
        ((l[0] - r[0]).powi(2) + (l[1] - r[1]).powi(2)).sqrt()
    }

    fn pose_bin(&self) -> usize {
        let [yaw, pitch, _] = self.descriptor();
        let yaw_bin = YAW_EDGES.iter().filter(|&&e| yaw > e).count();
        let pitch_bin = PITCH_EDGES.iter().filter(|&&e| pitch > e).count();
        pitch_bin * (YAW_EDGES.len() + 1) + yaw_bin
    }
}

/// Something the user should do something about, said once when it starts
/// (and again every [`REPEAT_SECONDS`] while it lasts).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Warning {
    /// Running time, seconds.
    pub at: f64,
    pub kind: WarningKind,
    pub message: String,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum WarningKind {
    RoomOverpowersMonitor,
    FaceLost,
    PoseFrozen,
    FewPairs,
}

struct ScreenFrame {
    t: f64,
    /// Mean linear luminance.
    luminance: f64,
    /// The light, averaged over 2 x 2 cells (planar RGB).
    light: Arc<[f32]>,
}

/// A usable frame, as the pairing sees it.
struct PairCandidate {
    t: f64,
    /// Eyes, nose tip, mouth in the frame's pixels.
    points: [[f32; 2]; 4],
    eye_distance: f32,
    light: Arc<[f32]>,
    paired: bool,
}

impl PairCandidate {
    fn matches(&self, other: &PairCandidate) -> bool {
        let scale = 0.5 * (self.eye_distance + other.eye_distance);
        let keypoints = self
            .points
            .iter()
            .zip(&other.points)
            .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt())
            .sum::<f32>()
            / (4.0 * scale.max(1.0));
        keypoints <= PAIR_KEYPOINT_DISTANCE && {
            let light = self
                .light
                .iter()
                .zip(other.light.iter())
                .map(|(a, b)| (a - b).abs())
                .sum::<f32>()
                / PAIR_LIGHT_LEN as f32;
            light >= PAIR_LIGHT_DIFFERENCE
        }
    }
}

/// A camera frame waiting for the screen frames around it.
struct Pending {
    t: f64,
    face: Option<Face>,
}

/// The measures so far, for the status line and the session's summary.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    pub camera_frames: u64,
    pub usable_frames: u64,
    /// Usable frames with at least one partner: the same pose under a different
    /// screen light ([`PAIR_KEYPOINT_DISTANCE`], [`PAIR_LIGHT_DIFFERENCE`]).
    pub pairable_frames: u64,
    pub frames_with_face: u64,
    /// The monitor's share of the face's light over the last [`SHARE_WINDOW_SECONDS`],
    /// when measurable.
    pub monitor_share_recent: Option<f64>,
    /// Over the whole session.
    pub monitor_share: Option<f64>,
    /// Keypoint spread over the last [`MOTION_WINDOW_SECONDS`].
    pub keypoint_spread_recent: Option<f64>,
    pub pose_bins_covered: usize,
    pub pose_bins: usize,
    /// Frames per pose bin: rows are head tilt (up to down), columns head turn.
    pub pose_bin_frames: Vec<Vec<u64>>,
    /// Seconds without a face in view, in total.
    pub face_lost_seconds: f64,
    pub warnings: Vec<Warning>,
}

#[derive(Default)]
pub struct Guidance {
    /// Screen frames, oldest first, the last [`SHARE_WINDOW_SECONDS`] and a little more.
    screen: VecDeque<ScreenFrame>,
    /// Last screen frame time seen.
    screen_latest: Option<f64>,
    pending: VecDeque<Pending>,
    /// (time, screen luminance, face luminance) of recent usable frames.
    pairs: VecDeque<(f64, f64, f64)>,
    /// Sums for the whole session's regression: n, Σx, Σy, Σxx, Σxy.
    totals: [f64; 5],
    /// (time, descriptor) of recent frames with a face.
    descriptors: VecDeque<(f64, [f64; 3])>,
    /// Every usable frame of the session, for pairing.
    pair_candidates: Vec<PairCandidate>,
    last_face: Option<f64>,
    first_frame: Option<f64>,
    last_frame: Option<f64>,
    summary: Summary,
    /// When each warning kind was last given; None while its condition is clear.
    warned: [Option<f64>; 4],
    new_warnings: Vec<Warning>,
}

fn kind_index(k: WarningKind) -> usize {
    match k {
        WarningKind::RoomOverpowersMonitor => 0,
        WarningKind::FaceLost => 1,
        WarningKind::PoseFrozen => 2,
        WarningKind::FewPairs => 3,
    }
}

impl Guidance {
    pub fn new() -> Guidance {
        Guidance {
            summary: Summary {
                pose_bins: POSE_BINS,
                pose_bin_frames: vec![vec![0; YAW_EDGES.len() + 1]; PITCH_EDGES.len() + 1],
                ..Summary::default()
            },
            ..Guidance::default()
        }
    }

    /// A screen frame shown at `t` seconds whose monitor light (the contract's
    /// grid, planar linear RGB) is `light`.
    pub fn screen(&mut self, t: f64, light: &[f32]) {
        self.screen.push_back(ScreenFrame {
            t,
            luminance: light_luminance(light),
            light: pairing_light(light),
        });
        self.screen_latest = Some(self.screen_latest.map_or(t, |l| l.max(t)));
        while self
            .screen
            .get(1)
            .is_some_and(|s| s.t < t - SHARE_WINDOW_SECONDS - 1.0)
        {
            self.screen.pop_front();
        }
        self.resolve(false);
    }

    /// A camera frame at `t` seconds, with the face found in it, if any.
    pub fn camera(&mut self, t: f64, face: Option<Face>) {
        self.pending.push_back(Pending { t, face });
        self.resolve(false);
    }

    /// Every stream has ended: judge the frames still waiting with what is known.
    pub fn finish(&mut self) {
        self.resolve(true);
        if let Some(end) = self.last_frame
            && self.last_face != Some(end)
        {
            let gap = self.time_without_face(end);
            if gap > FACE_LOST_SECONDS {
                self.summary.face_lost_seconds += gap;
            }
        }
    }

    /// Seconds from the last frame with a face (or the first frame) to `t`.
    fn time_without_face(&self, t: f64) -> f64 {
        t - self.last_face.or(self.first_frame).unwrap_or(t)
    }

    /// Warnings raised since the last call.
    pub fn take_warnings(&mut self) -> Vec<Warning> {
        std::mem::take(&mut self.new_warnings)
    }

    pub fn summary(&self) -> &Summary {
        &self.summary
    }

    /// Judges the camera frames whose light is known: a screen frame after
    /// them has arrived (so the latest one at or before them is final), or
    /// they have waited a second (the screen stalled), or the streams ended.
    fn resolve(&mut self, all: bool) {
        while let Some(p) = self.pending.front() {
            let known = self.screen_latest.is_some_and(|s| s > p.t);
            let newest = self.pending.back().map_or(p.t, |b| b.t);
            if !(all || known || newest - p.t > 1.0) {
                break;
            }
            let p = self.pending.pop_front().expect("checked above");
            self.judge(p);
        }
    }

    /// The latest screen frame at or before `t`.
    fn screen_at(&self, t: f64) -> Option<&ScreenFrame> {
        self.screen.iter().rev().find(|s| s.t <= t)
    }

    fn judge(&mut self, p: Pending) {
        let t = p.t;
        self.summary.camera_frames += 1;
        self.first_frame.get_or_insert(t);
        self.last_frame = Some(t);
        let light = self
            .screen_at(t)
            .map(|s| (s.luminance, Arc::clone(&s.light)));
        match p.face {
            Some(face) => {
                let gap = self.time_without_face(t);
                self.last_face = Some(t);
                self.clear(WarningKind::FaceLost);
                let s = &mut self.summary;
                s.frames_with_face += 1;
                if gap > FACE_LOST_SECONDS {
                    s.face_lost_seconds += gap;
                    // Motion is judged within a stretch of the face in view.
                    self.descriptors.clear();
                }
                let usable = face.height >= MIN_FACE_HEIGHT;
                if usable {
                    let bin = face.pose_bin();
                    let cols = YAW_EDGES.len() + 1;
                    s.pose_bin_frames[bin / cols][bin % cols] += 1;
                }
                if let (true, Some((screen, screen_light))) = (usable, light) {
                    s.usable_frames += 1;
                    self.pair(t, &face, screen_light);
                    let y = face.luminance;
                    self.pairs.push_back((t, screen, y));
                    let x = screen;
                    for (total, v) in self.totals.iter_mut().zip([1.0, x, y, x * x, x * y]) {
                        *total += v;
                    }
                }
                self.descriptors.push_back((t, face.descriptor()));
            }
            None => {
                let gap = self.time_without_face(t);
                if gap > FACE_LOST_SECONDS {
                    self.warn(
                        t,
                        WarningKind::FaceLost,
                        format!(
                            "no face for {gap:.1} s: sit facing the camera, your whole face in view"
                        ),
                    );
                }
            }
        }
        while self
            .pairs
            .front()
            .is_some_and(|&(tp, _, _)| tp < t - SHARE_WINDOW_SECONDS)
        {
            self.pairs.pop_front();
        }
        while self
            .descriptors
            .front()
            .is_some_and(|&(td, _)| td < t - MOTION_WINDOW_SECONDS)
        {
            self.descriptors.pop_front();
        }
        self.measure_share(t);
        self.measure_motion(t);
        self.judge_pairing(t);
        let s = &mut self.summary;
        s.pose_bins_covered = s
            .pose_bin_frames
            .iter()
            .flatten()
            .filter(|&&n| n > 0)
            .count();
    }

    /// Pairs the usable frame at `t` with every earlier one it matches.
    fn pair(&mut self, t: f64, face: &Face, light: Arc<[f32]>) {
        let mut new = PairCandidate {
            t,
            points: [face.eyes[0], face.eyes[1], face.nose, face.mouth],
            eye_distance: face.eye_distance(),
            light,
            paired: false,
        };
        for old in &mut self.pair_candidates {
            if old.matches(&new) {
                if !old.paired {
                    old.paired = true;
                    self.summary.pairable_frames += 1;
                }
                new.paired = true;
            }
        }
        if new.paired {
            self.summary.pairable_frames += 1;
        }
        self.pair_candidates.push(new);
    }

    /// Warns when few of the last [`PAIRING_WINDOW_SECONDS`] of usable frames
    /// pair: moving all the time, hardly a pose repeats.
    fn judge_pairing(&mut self, t: f64) {
        let Some(first) = self.pair_candidates.first() else {
            return;
        };
        if t - first.t < PAIRING_WINDOW_SECONDS {
            return;
        }
        let recent = self
            .pair_candidates
            .iter()
            .rev()
            .take_while(|c| c.t >= t - PAIRING_WINDOW_SECONDS);
        let (frames, paired) = recent.fold((0u64, 0u64), |(n, p), c| (n + 1, p + c.paired as u64));
        if frames > 0 && (paired as f64) < MIN_PAIRABLE_SHARE * frames as f64 {
            self.warn(
                t,
                WarningKind::FewPairs,
                format!(
                    "only {paired} of the last {frames} usable frames show a pose seen under \
                     other screen light, and only such pairs train the model: hold your head \
                     still for 2 to 3 s at a time while the screen changes, then move to a new \
                     pose"
                ),
            );
        } else {
            self.clear(WarningKind::FewPairs);
        }
    }

    fn measure_share(&mut self, t: f64) {
        let [n, sx, sy, sxx, sxy] = self.pairs.iter().fold([0.0; 5], |acc, &(_, x, y)| {
            [
                acc[0] + 1.0,
                acc[1] + x,
                acc[2] + y,
                acc[3] + x * x,
                acc[4] + x * y,
            ]
        });
        let recent = monitor_share(n, sx, sy, sxx, sxy);
        let [n, sx, sy, sxx, sxy] = self.totals;
        self.summary.monitor_share = monitor_share(n, sx, sy, sxx, sxy);
        self.summary.monitor_share_recent = recent;
        // Judged once the window is full, so a first noisy second does not warn.
        let span = self.pairs.front().map_or(0.0, |&(t0, _, _)| t - t0);
        match recent {
            Some(share) if share < MIN_MONITOR_SHARE && span >= MIN_SHARE_SECONDS => self.warn(
                t,
                WarningKind::RoomOverpowersMonitor,
                format!(
                    "the monitor gives only {:.0} % of the light on your face: the room \
                         overpowers it; dim the room lights or close the curtains, and turn \
                         the monitor's brightness up",
                    share * 100.0
                ),
            ),
            Some(_) => self.clear(WarningKind::RoomOverpowersMonitor),
            None => {}
        }
    }

    /// Judged on frames with a face only: a face out of view is the face-lost
    /// warning's business, not a still pose.
    fn measure_motion(&mut self, t: f64) {
        let n = self.descriptors.len();
        if self.last_face != Some(t) {
            return;
        }
        let span = self.descriptors.front().map_or(0.0, |&(t0, _)| t - t0);
        if n < 5 || span < MOTION_WINDOW_SECONDS * 0.8 {
            self.summary.keypoint_spread_recent = None;
            return;
        }
        let spread: f64 = (0..3)
            .map(|k| {
                let mean = self.descriptors.iter().map(|(_, d)| d[k]).sum::<f64>() / n as f64;
                let var = self
                    .descriptors
                    .iter()
                    .map(|(_, d)| (d[k] - mean).powi(2))
                    .sum::<f64>()
                    / n as f64;
                var.sqrt()
            })
            .sum();
        self.summary.keypoint_spread_recent = Some(spread);
        if spread < MIN_KEYPOINT_SPREAD {
            self.warn(
                t,
                WarningKind::PoseFrozen,
                format!(
                    "your pose and expression have barely changed for {MOTION_WINDOW_SECONDS:.0} s: \
                     turn and tilt your head, talk, smile, look around the screen"
                ),
            );
        } else {
            self.clear(WarningKind::PoseFrozen);
        }
    }

    fn warn(&mut self, t: f64, kind: WarningKind, message: String) {
        let last = &mut self.warned[kind_index(kind)];
        if last.is_some_and(|l| t - l < REPEAT_SECONDS) {
            return;
        }
        *last = Some(t);
        let w = Warning {
            at: t,
            kind,
            message,
        };
        self.summary.warnings.push(w.clone());
        self.new_warnings.push(w);
    }

    fn clear(&mut self, kind: WarningKind) {
        self.warned[kind_index(kind)] = None;
    }
}

/// The monitor's share of the face's light from a regression of face luminance
/// on screen luminance (sums of n pairs): the part of the face's mean that
/// follows the screen, slope × mean screen / mean face, in [0, 1]. None when
/// the screen's brightness has not varied enough to tell.
fn monitor_share(n: f64, sx: f64, sy: f64, sxx: f64, sxy: f64) -> Option<f64> {
    if n < 10.0 {
        return None;
    }
    let (mx, my) = (sx / n, sy / n);
    let var_x = sxx / n - mx * mx;
    if var_x.max(0.0).sqrt() < MIN_SCREEN_VARIATION || my <= 0.0 {
        return None;
    }
    let slope = (sxy / n - mx * my) / var_x;
    Some((slope * mx / my).clamp(0.0, 1.0))
}

/// Mean linear luminance (Rec. 709 weights) of the inner part of a face box
/// (the middle half of its width, from 20 % to 80 % of its height), in a
/// packed 8-bit sRGB frame: skin, not hair or background.
pub fn face_luminance(
    rgb: &[u8],
    stride: usize,
    width: usize,
    height: usize,
    centre: [f32; 2],
    size: [f32; 2],
) -> f64 {
    let span = |c: f32, half: f32, extent: usize| {
        let a = (c - half).max(0.0) as usize;
        let b = ((c + half).max(0.0) as usize).min(extent);
        a..b
    };
    let xs = span(centre[0], size[0] / 4.0, width);
    let ys = span(centre[1], size[1] * 0.3, height);
    let (mut sum, mut n) = (0.0, 0usize);
    for y in ys {
        let row = &rgb[y * stride..];
        for x in xs.clone() {
            let p = &row[x * 3..x * 3 + 3];
            let [r, g, b] = [p[0], p[1], p[2]].map(|v| srgb_byte_to_linear(v) as f64);
            sum += 0.2126 * r + 0.7152 * g + 0.0722 * b;
            n += 1;
        }
    }
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// The light averaged over blocks of 2 x 2 cells, for pairing.
fn pairing_light(planar_rgb: &[f32]) -> Arc<[f32]> {
    let (rows, cols) = (LIGHT_ROWS / 2, LIGHT_COLS / 2);
    debug_assert_eq!(planar_rgb.len(), 3 * LIGHT_ROWS * LIGHT_COLS);
    let mut out = vec![0.0f32; PAIR_LIGHT_LEN];
    for c in 0..3 {
        for y in 0..LIGHT_ROWS {
            for x in 0..LIGHT_COLS {
                out[(c * rows + y / 2) * cols + x / 2] +=
                    0.25 * planar_rgb[(c * LIGHT_ROWS + y) * LIGHT_COLS + x];
            }
        }
    }
    out.into()
}

/// Mean linear luminance of a monitor light (planar linear RGB, cells equal in area).
fn light_luminance(planar_rgb: &[f32]) -> f64 {
    let n = planar_rgb.len() / 3;
    let mean = |c: usize| {
        planar_rgb[c * n..(c + 1) * n]
            .iter()
            .map(|&v| v as f64)
            .sum::<f64>()
            / n.max(1) as f64
    };
    0.2126 * mean(0) + 0.7152 * mean(1) + 0.0722 * mean(2)
}

#[cfg(test)]
mod tests;
