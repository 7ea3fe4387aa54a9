//! The monitor-match check (the paper's section 4.3): does the light on the face
//! agree with what the screen showed?
//!
//! The network predicts the monitor's light from the face alone. A live face lit
//! by the screen it faces follows that screen; a replayed or synthesised one
//! does not, or follows it late. Over a sliding window this module correlates
//! the screen's light with the light predicted from the face, frame by frame, in
//! four components:
//!
//! - **luminance**: the log of the mean linear luminance (Rec. 709 weights);
//! - **luminance change**: how the log luminance changed over the last 0.1 s, which
//!   pins down *when* the screen changed, so a face that follows it late fails;
//! - **colour**: blue minus red, over the sum of the channels;
//! - **spatial**: left half minus right half of the luminance, over their sum.
//!
//! Each is a Pearson correlation over the window, and counts only where the screen
//! itself varied enough in the window to tell anything: a still screen cannot be
//! checked. The score is the mean of the two luminance components. Colour and
//! spatial are reported but not scored: on the simulator the network's predicted
//! hue does not follow the screen's (its correlation is strongly negative on some
//! recordings and positive on others) and its left-right balance only weakly,
//! and adding them lowered the check's AUC (`examples/match_check.rs` measures
//! each component alone). No GStreamer here: the element feeds it a pair of
//! lights per face frame.

use std::collections::VecDeque;

use crate::light::{LIGHT_COLS, LIGHT_ROWS, Light};

/// Rec. 709 luminance weights of linear RGB.
const LUMA: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// Keeps the ratios finite for a black light.
const RATIO_FLOOR: f64 = 1e-3;
/// Added to the luminance before its log, so black and near-black screens do not
/// dominate: about the light of a dim grey screen.
const LOG_FLOOR: f64 = 0.01;
/// The luminance change is measured over this many seconds.
const CHANGE_SPAN: f64 = 0.1;

/// The measures of one light the check correlates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Features {
    pub luminance: f64,
    pub colour: f64,
    pub spatial: f64,
}

impl Features {
    pub fn of(light: &Light) -> Features {
        let n = LIGHT_ROWS * LIGHT_COLS;
        let plane = |c: usize| &light.0[c * n..(c + 1) * n];
        let mean = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
        let (r, g, b) = (mean(plane(0)), mean(plane(1)), mean(plane(2)));
        // Luminance of the left and right halves of the screen, as the user sees it.
        let mut halves = [0f64; 2];
        for (c, weight) in LUMA.iter().enumerate() {
            for (i, v) in plane(c).iter().enumerate() {
                let right = (i % LIGHT_COLS >= LIGHT_COLS / 2) as usize;
                halves[right] += (*weight * v) as f64;
            }
        }
        let half = (n / 2) as f64;
        let (left, right) = (halves[0] / half, halves[1] / half);
        Features {
            luminance: (left + right) / 2.0,
            colour: (b - r) / (r + g + b).max(RATIO_FLOOR),
            spatial: (left - right) / (left + right).max(RATIO_FLOOR),
        }
    }

    fn log_luminance(&self) -> f64 {
        (self.luminance + LOG_FLOOR).ln()
    }
}

/// What the check compares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Component {
    Luminance,
    LuminanceChange,
    Colour,
    Spatial,
}

impl Component {
    pub const ALL: [Component; 4] = [
        Component::Luminance,
        Component::LuminanceChange,
        Component::Colour,
        Component::Spatial,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Component::Luminance => "luminance",
            Component::LuminanceChange => "luminance-change",
            Component::Colour => "colour",
            Component::Spatial => "spatial",
        }
    }

    /// Weight in the score.
    fn weight(self) -> f64 {
        match self {
            Component::Luminance | Component::LuminanceChange => 1.0,
            Component::Colour => 0.0,
            Component::Spatial => 0.0,
        }
    }

    /// Standard deviation of the screen's feature over the window below which the
    /// screen did not vary enough for the component to count.
    fn min_screen_std(self) -> f64 {
        match self {
            // Log units: the screen's brightness varied by about 5%.
            Component::Luminance => 0.05,
            Component::LuminanceChange => 0.01,
            Component::Colour => 0.02,
            Component::Spatial => 0.02,
        }
    }
}

/// The check's settings (the element's `match-window` and `match-threshold`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatchSettings {
    /// Seconds of frames the score covers.
    pub window: f64,
    /// Score at or above which the face matches the screen.
    pub threshold: f64,
    /// Share of the window that must hold frames with a prediction: a window the
    /// face was mostly away for cannot be checked.
    pub min_coverage: f64,
}

pub const DEFAULT_WINDOW: f64 = 5.0;
/// On the simulator (`examples/match_check.rs`) every genuine window of 3 or 5 s
/// scored above 0.63, and about 6% of the impostor ones reached 0.6.
pub const DEFAULT_THRESHOLD: f64 = 0.6;

impl Default for MatchSettings {
    fn default() -> Self {
        MatchSettings {
            window: DEFAULT_WINDOW,
            threshold: DEFAULT_THRESHOLD,
            min_coverage: 0.5,
        }
    }
}

/// The check's result over one window.
#[derive(Clone, Debug, PartialEq)]
pub struct MatchScore {
    /// Weighted mean of the components that count; None when none does.
    pub score: Option<f64>,
    /// Each component's correlation, None where the screen did not vary enough.
    pub components: [(Component, Option<f64>); 4],
    /// Frames in the window, and the seconds they span.
    pub frames: usize,
    pub span: f64,
    pub verdict: Verdict,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// The light on the face follows the screen.
    Match,
    /// It does not: a replayed or synthesised face, or a face not lit by this screen.
    Mismatch,
    /// Too few frames with a face in the window.
    TooFewFrames,
    /// The screen did not change enough in the window to tell.
    StillScreen,
}

impl Verdict {
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Match => "match",
            Verdict::Mismatch => "mismatch",
            Verdict::TooFewFrames => "too-few-frames",
            Verdict::StillScreen => "still-screen",
        }
    }
}

/// Pearson correlation of pairs; None when either side does not vary (`min_std`
/// for the first, the screen's).
pub fn correlation(pairs: &[(f64, f64)], min_std: f64) -> Option<f64> {
    let n = pairs.len() as f64;
    if pairs.len() < 3 {
        return None;
    }
    let (ma, mb) = pairs
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0);
    for (x, y) in pairs {
        let (da, db) = (x - ma, y - mb);
        saa += da * da;
        sbb += db * db;
        sab += da * db;
    }
    let (sa, sb) = ((saa / n).sqrt(), (sbb / n).sqrt());
    if sa < min_std || sb < 1e-9 {
        return None;
    }
    Some(sab / n / (sa * sb))
}

/// The screen's and the prediction's features of the frames in the window.
#[derive(Clone, Debug, Default)]
pub struct MatchWindow {
    /// (time in seconds, screen, predicted), oldest first.
    samples: VecDeque<(f64, Features, Features)>,
}

impl MatchWindow {
    /// Adds a face frame at `time` (seconds, increasing), lit by `screen`, whose
    /// face gave `predicted`; frames older than `window` seconds before it leave.
    pub fn push(&mut self, time: f64, screen: &Light, predicted: &Light, window: f64) {
        self.push_features(time, Features::of(screen), Features::of(predicted), window);
    }

    pub fn push_features(&mut self, time: f64, screen: Features, predicted: Features, window: f64) {
        if self.samples.back().is_some_and(|(t, _, _)| time < *t) {
            // Time went back (a seek the element did not reset for): start afresh.
            self.samples.clear();
        }
        self.samples.push_back((time, screen, predicted));
        self.advance(time, window);
    }

    /// Lets the frames older than `window` seconds before `time` leave, when no
    /// pair came for a while (no face, or the monitor stream stalled).
    pub fn advance(&mut self, time: f64, window: f64) {
        while self
            .samples
            .front()
            .is_some_and(|(t, _, _)| *t <= time - window)
        {
            self.samples.pop_front();
        }
    }

    pub fn reset(&mut self) {
        self.samples.clear();
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The (screen, predicted) values of one component over the window.
    fn pairs(&self, component: Component, fps: f64) -> Vec<(f64, f64)> {
        let value = |(_, s, p): &(f64, Features, Features)| match component {
            Component::Luminance | Component::LuminanceChange => {
                (s.log_luminance(), p.log_luminance())
            }
            Component::Colour => (s.colour, p.colour),
            Component::Spatial => (s.spatial, p.spatial),
        };
        if component != Component::LuminanceChange {
            return self.samples.iter().map(value).collect();
        }
        // Changes over CHANGE_SPAN between samples that far apart; frames missing
        // in between (no face) leave their changes out.
        let lag = ((CHANGE_SPAN * fps).round() as usize).max(1);
        let longest = (lag as f64 + 0.5) / fps;
        let samples: Vec<_> = self.samples.iter().collect();
        samples
            .windows(lag + 1)
            .filter(|w| w[lag].0 - w[0].0 <= longest)
            .map(|w| {
                let ((s0, p0), (s1, p1)) = (value(w[0]), value(w[lag]));
                (s1 - s0, p1 - p0)
            })
            .collect()
    }

    /// Scores the window; `fps` is the face stream's frame rate, which says how
    /// many frames a full window holds.
    pub fn score(&self, settings: &MatchSettings, fps: f64) -> MatchScore {
        let frames = self.samples.len();
        let span = match (self.samples.front(), self.samples.back()) {
            (Some(a), Some(b)) => b.0 - a.0,
            _ => 0.0,
        };
        let components =
            Component::ALL.map(|c| (c, correlation(&self.pairs(c, fps), c.min_screen_std())));
        let (sum, weights) = components
            .iter()
            .filter(|(c, _)| c.weight() > 0.0)
            .filter_map(|(c, r)| r.map(|r| (c.weight() * r, c.weight())))
            .fold((0.0, 0.0), |(s, w), (a, b)| (s + a, w + b));
        let score = (weights > 0.0).then(|| sum / weights);
        let verdict = if (frames as f64) < settings.min_coverage * settings.window * fps {
            Verdict::TooFewFrames
        } else {
            match score {
                None => Verdict::StillScreen,
                Some(s) if s >= settings.threshold => Verdict::Match,
                Some(_) => Verdict::Mismatch,
            }
        };
        MatchScore {
            score,
            components,
            frames,
            span,
            verdict,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FPS: f64 = 30.0;

    /// A screen that cuts between brightness levels at uneven times, as content does.
    fn screen_at(frame: usize) -> f64 {
        const LEVELS: [f64; 7] = [0.05, 0.6, 0.2, 0.9, 0.1, 0.4, 0.7];
        const CUTS: [usize; 7] = [0, 17, 41, 52, 80, 95, 121];
        let segment = CUTS.iter().rposition(|&c| c <= frame % 150).unwrap();
        LEVELS[(segment + frame / 150) % LEVELS.len()]
    }

    fn grey(v: f64) -> Light {
        Light::uniform([v as f32; 3])
    }

    /// A prediction of a screen `v`: duller, offset, and with a deterministic wobble.
    fn predicted(v: f64, frame: usize) -> Light {
        let wobble = 0.02 * ((frame * 7919) % 13) as f64 / 13.0;
        grey(0.05 + 0.5 * v + wobble)
    }

    /// Scores `frames` frames of a face lit by the screen `delay` frames before what
    /// the check is shown.
    fn run(frames: usize, delay: usize, settings: &MatchSettings) -> MatchScore {
        let mut w = MatchWindow::default();
        for i in delay..frames {
            let t = i as f64 / FPS;
            w.push(
                t,
                &grey(screen_at(i)),
                &predicted(screen_at(i - delay), i),
                settings.window,
            );
        }
        w.score(settings, FPS)
    }

    #[test]
    fn features_measure_brightness_hue_and_balance() {
        let white = Features::of(&grey(0.5));
        assert!((white.luminance - 0.5).abs() < 1e-6);
        assert!(white.colour.abs() < 1e-9 && white.spatial.abs() < 1e-9);
        let blue = Features::of(&Light::uniform([0.0, 0.0, 0.6]));
        assert!((blue.colour - 1.0).abs() < 1e-6, "{blue:?}");
        let red = Features::of(&Light::uniform([0.6, 0.0, 0.0]));
        assert!((red.colour + 1.0).abs() < 1e-6, "{red:?}");
        // Only the left half of the screen (as the user sees it) lit.
        let mut left = grey(0.0);
        for (i, v) in left.0.iter_mut().enumerate() {
            if i % LIGHT_COLS < LIGHT_COLS / 2 {
                *v = 0.8;
            }
        }
        let left = Features::of(&left);
        assert!((left.spatial - 1.0).abs() < 1e-6, "{left:?}");
        assert!((left.luminance - 0.4).abs() < 1e-6);
    }

    #[test]
    fn correlation_is_signed_and_needs_variation() {
        let up: Vec<_> = (0..10).map(|i| (i as f64, 2.0 * i as f64 + 1.0)).collect();
        assert!((correlation(&up, 0.0).unwrap() - 1.0).abs() < 1e-12);
        let down: Vec<_> = (0..10).map(|i| (i as f64, -(i as f64))).collect();
        assert!((correlation(&down, 0.0).unwrap() + 1.0).abs() < 1e-12);
        let still: Vec<_> = (0..10).map(|i| (1.0, i as f64)).collect();
        assert_eq!(
            correlation(&still, 0.01),
            None,
            "a still screen tells nothing"
        );
        let barely: Vec<_> = (0..10).map(|i| (i as f64 * 1e-4, i as f64)).collect();
        assert_eq!(correlation(&barely, 0.01), None, "below the screen's floor");
        assert_eq!(correlation(&up[..2], 0.0), None, "too few pairs");
    }

    #[test]
    fn a_face_lit_by_the_screen_matches() {
        let s = run(300, 0, &MatchSettings::default());
        assert_eq!(s.verdict, Verdict::Match, "{s:?}");
        assert!(s.score.unwrap() > 0.9, "{s:?}");
        assert_eq!(s.frames, 150, "5 s at 30 fps");
        assert!((s.span - 149.0 / FPS).abs() < 1e-9);
        // A grey screen has no hue nor balance to compare.
        let named = |c| s.components.iter().find(|(k, _)| *k == c).unwrap().1;
        assert!(named(Component::Luminance).unwrap() > 0.9);
        assert!(named(Component::LuminanceChange).unwrap() > 0.9);
        assert_eq!(named(Component::Colour), None);
        assert_eq!(named(Component::Spatial), None);
    }

    #[test]
    fn a_face_that_follows_the_screen_late_does_not() {
        for delay in [15, 30, 60] {
            let s = run(300, delay, &MatchSettings::default());
            assert_eq!(s.verdict, Verdict::Mismatch, "delay {delay} frames: {s:?}");
        }
    }

    #[test]
    fn a_face_lit_by_another_screen_does_not() {
        let settings = MatchSettings::default();
        let mut w = MatchWindow::default();
        for i in 0..300 {
            // The other screen: the same kind of content, cut at other times.
            let other = screen_at(i + 400);
            w.push(
                i as f64 / FPS,
                &grey(screen_at(i)),
                &predicted(other, i),
                settings.window,
            );
        }
        let s = w.score(&settings, FPS);
        assert_eq!(s.verdict, Verdict::Mismatch, "{s:?}");
    }

    #[test]
    fn a_still_screen_or_an_absent_face_gives_no_verdict() {
        let settings = MatchSettings::default();
        let mut still = MatchWindow::default();
        for i in 0..300 {
            still.push(
                i as f64 / FPS,
                &grey(0.5),
                &predicted(0.5, i),
                settings.window,
            );
        }
        let s = still.score(&settings, FPS);
        assert_eq!((s.verdict, s.score), (Verdict::StillScreen, None));
        // 2 s of frames with a face in a 5 s window.
        let s = run(60, 0, &settings);
        assert_eq!(s.verdict, Verdict::TooFewFrames, "{s:?}");
        assert!(s.score.is_some(), "the score is still given");
    }

    #[test]
    fn the_window_slides_and_restarts_when_time_goes_back() {
        let mut w = MatchWindow::default();
        for i in 0..100 {
            w.push(i as f64 / FPS, &grey(0.5), &grey(0.5), 1.0);
        }
        assert_eq!(w.len(), 30, "1 s at 30 fps");
        // Half a second after the last frame: its last half second stays.
        w.advance(99.0 / FPS + 0.51, 1.0);
        assert_eq!(
            w.len(),
            15,
            "frames without a pair still move the window on"
        );
        w.push(0.0, &grey(0.5), &grey(0.5), 1.0);
        assert_eq!(w.len(), 1);
        w.reset();
        assert!(w.is_empty());
    }

    #[test]
    fn the_threshold_decides() {
        let strict = MatchSettings {
            threshold: 1.0,
            ..MatchSettings::default()
        };
        assert_eq!(run(300, 0, &strict).verdict, Verdict::Mismatch);
        let lax = MatchSettings {
            threshold: -1.0,
            ..MatchSettings::default()
        };
        assert_eq!(run(300, 30, &lax).verdict, Verdict::Match);
    }
}
