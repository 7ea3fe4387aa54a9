//! The per-frame policy: what happens to each face frame of one video stream,
//! and the state the stream carries from frame to frame.
//!
//! Given a frame, its face region, its source light and whether it is already
//! late, [`FramePolicy::process`] decides and carries out one of:
//!
//! - **pass through**, untouched: no face is followed, the region is too dark to
//!   carry light to change (black frames stay black), nobody is in view, the source light already is the
//!   target, or the network broke (NaN/Inf);
//! - **reuse** the last relighting, carried onto this frame: the frame is late
//!   (QoS), or the network ran less than `reuse-interval` frames ago and neither
//!   the picture nor the light changed much since (sensor noise does not count,
//!   a cut or a big motion does);
//! - **relight**: run the network, with the paper's temporal filters (source-light
//!   averaging and de-lit feature smoothing, [`super::temporal`]), the face's
//!   colour taken from the target spread evenly ([`super::spread_colour`]).
//!
//! Its [`Outcome`] names the action, why, and the lighting change to paste onto
//! the frame. The temporal state is forgotten in one place, [`FramePolicy::reset`].
//! No GStreamer here: the element wires frames to it.

use std::fmt;
use std::time::Instant;

use crate::parallel::beside_long;

use super::colour_tracking::{self, ColourTracker, face_colour};
use super::relighter::{Relighter, Relit, timed};
use super::runtime::EngineError;
use super::spread_colour::{self, SpreadColour};
use super::temporal::{FeatureSmoother, PredictionSmoother, SourceLightAverager, Temporal};
use crate::engine::contract::PRESENCE_SIZE;
use crate::frame::{
    Crop, FacePlace, Frame, LightingChange, mean_luma, resample_square, sample_crop,
};
use crate::light::Light;

/// Where this frame's source light comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// The monitor's content at the frame's time.
    Known(Light),
    /// Nothing is known: the network predicts it (unknown-source mode).
    Unknown,
}

/// Mean sRGB luma of the face region below which a frame carries no light to
/// change: camera start-up, fades and cuts to black. Relighting such a frame can
/// only invent light (a ghost of the face the network has learnt), so it passes.
pub const DARK_LEVEL: f32 = 0.03;

/// The scene-adaptive skips and their thresholds (the element's properties).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Skips {
    /// The network runs at least every this many frames; the frames in between
    /// carry the last relighting (1: every frame runs the network).
    pub reuse_interval: u32,
    /// Mean absolute change of the network's input (sRGB, [0, 1]) since the network
    /// last ran beyond which it runs at once: a cut or a big motion. Sensor noise of
    /// a still face is about 0.0044.
    pub reuse_threshold: f32,
    /// Mean absolute change of the averaged source light (linear) beyond which the
    /// network runs at once.
    pub reuse_light_threshold: f32,
    /// Pass through when the source light is the target light.
    pub skip_same_light: bool,
    /// Mean absolute difference (linear) under which source and target are the same.
    pub same_light_tolerance: f32,
    /// Pass through while the presence stage sees nobody.
    pub skip_absent: bool,
    pub presence_threshold: f32,
}

impl Default for Skips {
    // From the benchmark's skip table (docs/benchmark.md, "Skipping what a scene does not need"):
    // each skip is on where it pays.
    fn default() -> Self {
        Skips {
            reuse_interval: DEFAULT_REUSE_INTERVAL,
            reuse_threshold: 0.02,
            reuse_light_threshold: 0.002,
            skip_same_light: true,
            same_light_tolerance: 0.004,
            skip_absent: true,
            presence_threshold: 0.5,
        }
    }
}

/// How often the network runs at least, by default (`reuse-interval`).
pub const DEFAULT_REUSE_INTERVAL: u32 = 3;

/// One face frame, as the policy needs it.
pub struct FrameRequest<'a> {
    pub frame: &'a Frame<'a>,
    /// The face region.
    pub crop: Crop,
    /// Where the face is in it.
    pub face: FacePlace,
    /// How much of the relighting to show, in [0, 1]: a followed face fading in or
    /// out; 0 when no face is followed.
    pub strength: f32,
    pub source: Source,
    /// Already past its deadline: reuse the last relighting if there is one.
    pub late: bool,
    /// Predict the source light even when it is known (someone shows the prediction).
    pub want_prediction: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reuse {
    /// The network ran less than `reuse-interval` frames ago, and the face region
    /// and the source light changed little since.
    Interval,
    /// The frame is already late (QoS).
    Late,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PassThrough {
    /// No face is followed.
    NoFace,
    /// The face region is too dark to carry light ([`DARK_LEVEL`]).
    Dark,
    /// The presence stage sees nobody.
    Absent,
    /// The source light is the target light.
    SameLight,
    /// The network produced NaN or Inf.
    NonFinite,
}

/// What was done with a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    Relit,
    Reused(Reuse),
    PassedThrough(PassThrough),
}

/// The result of one frame.
pub struct Outcome<'a> {
    pub action: Action,
    /// The lighting change to paste onto the frame's face region; None leaves it as it is.
    pub change: Option<&'a LightingChange>,
    /// How much of the change to show, in [0, 1].
    pub strength: f32,
    /// The predicted source monitor light, when there is one for this frame.
    pub predicted: Option<Light>,
    /// What the decision was based on, for the debug log.
    pub luma: f32,
    pub presence: Option<f32>,
    /// Mean absolute change of the network's input since the network last ran.
    pub change_since_network: f32,
}

impl fmt::Display for Outcome<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.action {
            Action::Relit => write!(f, "relit by the network"),
            Action::Reused(Reuse::Late) => {
                write!(f, "carried the last relighting: the frame is late (QoS)")
            }
            Action::Reused(Reuse::Interval) => write!(
                f,
                "carried the last relighting: the network ran recently and little changed since (change {:.4})",
                self.change_since_network
            ),
            Action::PassedThrough(PassThrough::NoFace) => {
                write!(f, "passed through: no face is followed")
            }
            Action::PassedThrough(PassThrough::Dark) => write!(
                f,
                "passed through: the face region is dark (mean luma {:.3} < {DARK_LEVEL})",
                self.luma
            ),
            Action::PassedThrough(PassThrough::Absent) => write!(
                f,
                "passed through: nobody in view (presence {:.2})",
                self.presence.unwrap_or(0.0)
            ),
            Action::PassedThrough(PassThrough::SameLight) => {
                write!(f, "passed through: the source light is the target light")
            }
            Action::PassedThrough(PassThrough::NonFinite) => write!(
                f,
                "passed through: the network produced NaN or Inf; temporal state reset"
            ),
        }
    }
}

/// The network's result for one image, with the stream's temporal state.
#[derive(Clone, Debug)]
pub struct FrameOutput {
    /// Planar sRGB in [0, 1], 3 × R × R; None when the model produced NaN or Inf.
    pub relit: Option<Vec<f32>>,
    /// The predicted source monitor light, when it was computed.
    pub predicted: Option<Light>,
    /// The (averaged) source light the frame was de-lit with.
    pub source: Light,
}

/// Work done and time spent, for statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PolicyCounts {
    pub relit: u64,
    pub reused_interval: u64,
    pub passed_no_face: u64,
    pub reused_late: u64,
    pub passed_dark: u64,
    pub passed_absent: u64,
    pub passed_same_light: u64,
    pub passed_non_finite: u64,
    /// Resets that forgot something.
    pub resets: u64,
    pub target_encodes: u64,
    /// Second decodes, with the target spread evenly ([`super::spread_colour`]).
    pub spread_decodes: u64,
    /// Codes computed for the averaged source light: one per change of it.
    pub source_encodes: u64,
    pub predictions: u64,
    /// Seconds inside ONNX Runtime for frames, every stage; not encoding targets,
    /// which happens outside the frames' turn (at start) or in the element's setup.
    pub network_seconds: f64,
    /// Seconds averaging source lights and smoothing features.
    pub filter_seconds: f64,
    /// Seconds reading the face region into the network's input.
    pub crop_seconds: f64,
    /// Seconds building the lighting change to paste.
    pub change_seconds: f64,
}

/// What [`FramePolicy::prepare`] decided for a frame.
pub enum Prepared {
    /// Passed through, or the last change carried, with no network: the
    /// outcome, whose change [`FramePolicy::decided`] fills in.
    Decided(Outcome<'static>),
    /// The network is to run ([`FramePolicy::finish`]).
    Relight(Pending),
}

/// A frame's network input and what the policy decided about it so far:
/// what [`FramePolicy::finish`] needs, with no borrow of the frame.
pub struct Pending {
    image: Vec<f32>,
    crop: Crop,
    face: FacePlace,
    source: Source,
    want_prediction: bool,
    average: Option<Light>,
    /// The outcome as far as it is known: the network's result completes it.
    so_far: Outcome<'static>,
}

/// What a relit frame leaves for the frames that reuse it.
struct Processed {
    /// The network's input, and the averaged source light.
    image: Vec<f32>,
    average: Light,
    change: LightingChange,
    crop: Crop,
    predicted: Option<Light>,
    /// Frames that carried this relighting since the network ran.
    carried: u32,
}

pub struct FramePolicy {
    relighter: Relighter,
    temporal: Temporal,
    skips: Skips,
    averager: SourceLightAverager,
    smoother: FeatureSmoother,
    predictions: PredictionSmoother,
    colours: ColourTracker,
    /// The target light and its code, computed once per target.
    target: Option<(Light, Vec<f32>)>,
    /// Whether the face's colour comes from the target spread evenly.
    spread_colour_on: bool,
    /// The target spread evenly, its code and the colour it gives.
    spread_colour: SpreadColour,
    /// The source light of the last frame that ran the network, before averaging.
    last_source: Option<Light>,
    /// The last averaged source light and its code.
    source_code: Option<(Light, Vec<f32>)>,
    /// Seconds in ONNX Runtime encoding target lights.
    target_network_seconds: f64,
    last: Option<Processed>,
    counts: PolicyCounts,
}

/// Mean absolute difference of two images of the same size.
fn mean_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f32>() / a.len() as f32
}

impl FramePolicy {
    pub fn new(relighter: Relighter, temporal: Temporal, skips: Skips) -> FramePolicy {
        FramePolicy {
            relighter,
            temporal,
            skips,
            averager: SourceLightAverager::new(temporal.beta, temporal.average_frames),
            smoother: FeatureSmoother::new(temporal.alpha),
            predictions: PredictionSmoother::new(temporal.prediction_weight),
            colours: ColourTracker::new(colour_tracking::SLOW_MEAN_WEIGHT),
            target: None,
            spread_colour_on: true,
            spread_colour: SpreadColour::default(),
            last_source: None,
            source_code: None,
            target_network_seconds: 0.0,
            last: None,
            counts: PolicyCounts::default(),
        }
    }

    pub fn relighter(&self) -> &Relighter {
        &self.relighter
    }

    pub fn counts(&self) -> PolicyCounts {
        PolicyCounts {
            network_seconds: self.relighter.time().seconds - self.target_network_seconds,
            ..self.counts
        }
    }

    /// Forgets everything learnt from past frames: averaged lights, smoothed features
    /// and the last relighting. Returns whether there was anything to forget (only
    /// such resets are counted).
    pub fn reset(&mut self) -> bool {
        let had_state = self.smoother.has_state() || !self.averager.is_empty();
        self.averager.reset();
        self.smoother.reset();
        self.predictions.reset();
        self.colours.reset();
        self.spread_colour.forget();
        self.last_source = None;
        self.last = None;
        if had_state {
            self.counts.resets += 1;
        }
        had_state
    }

    /// Changes the temporal filters; their state starts afresh.
    pub fn set_temporal(&mut self, temporal: Temporal) {
        if temporal != self.temporal {
            self.temporal = temporal;
            self.averager = SourceLightAverager::new(temporal.beta, temporal.average_frames);
            self.smoother = FeatureSmoother::new(temporal.alpha);
            self.predictions = PredictionSmoother::new(temporal.prediction_weight);
            self.colours.reset();
            self.last = None;
        }
    }

    pub fn set_skips(&mut self, skips: Skips) {
        self.skips = skips;
    }

    /// Whether the face's colour comes from the target spread evenly
    /// ([`super::spread_colour`]); on by default.
    pub fn set_spread_colour(&mut self, on: bool) {
        if on != self.spread_colour_on {
            self.spread_colour_on = on;
            // While off no network frame counted the difference's age.
            self.spread_colour.forget();
            self.last = None;
        }
    }

    /// The target light, if one is set.
    pub fn target(&self) -> Option<&Light> {
        self.target.as_ref().map(|(l, _)| l)
    }

    /// Sets the target light; its code is computed here, once, and reused every frame.
    pub fn set_target(&mut self, light: &Light) -> Result<(), EngineError> {
        if self.target().is_some_and(|l| l == light) {
            return Ok(());
        }
        let jumped = self
            .target()
            .is_none_or(|old| old.distance(light) > spread_colour::LIGHT_JUMP);
        let before = self.relighter.time().seconds;
        let code = self.relighter.encode_light(light);
        self.target_network_seconds += self.relighter.time().seconds - before;
        let code = code?;
        self.counts.target_encodes += 1;
        self.target = Some((light.clone(), code));
        self.spread_colour.retarget(light, jumped);
        self.last = None;
        Ok(())
    }

    /// The last frame's de-lit features f1..f7 after smoothing.
    pub fn smoothed_features(&self) -> Option<&[Vec<f32>]> {
        self.smoother.state()
    }

    /// Decides what happens to one frame and does it, but for pasting the
    /// returned change onto the frame.
    pub fn process(&mut self, request: FrameRequest) -> Result<Outcome<'_>, EngineError> {
        match self.prepare(request)? {
            Prepared::Decided(decided) => Ok(self.decided(decided)),
            Prepared::Relight(pending) => self.finish(pending),
        }
    }

    /// The first half of [`FramePolicy::process`]: reads the frame and
    /// decides, without the network, whether it passes through or carries
    /// the last change; or what the network is to run on, which holds nothing
    /// of the frame, so the frame can be written while the network runs
    /// ([`FramePolicy::finish`]).
    pub fn prepare(&mut self, request: FrameRequest) -> Result<Prepared, EngineError> {
        let FrameRequest {
            frame,
            crop,
            face,
            strength,
            source,
            late,
            want_prediction,
        } = request;
        if strength <= 0.0 {
            // Nobody to relight; by the time a face is back, nothing from before applies.
            self.counts.passed_no_face += 1;
            self.reset();
            return Ok(Prepared::Decided(Outcome {
                action: Action::PassedThrough(PassThrough::NoFace),
                change: None,
                strength,
                predicted: None,
                luma: 0.0,
                presence: None,
                change_since_network: 0.0,
            }));
        }
        let res = self.relighter.resolution();
        let image = timed(&mut self.counts.crop_seconds, || {
            sample_crop(frame, crop, res)
        });
        let luma = mean_luma(&image);
        let passed = |action, presence| Outcome {
            action: Action::PassedThrough(action),
            change: None,
            strength,
            predicted: None,
            luma,
            presence,
            change_since_network: 0.0,
        };
        if luma < DARK_LEVEL {
            // The person (or the picture) will have changed by the time there is
            // light again: nothing from before carries over.
            self.counts.passed_dark += 1;
            self.reset();
            return Ok(Prepared::Decided(passed(PassThrough::Dark, None)));
        }
        let mut presence = None;
        if self.skips.skip_absent && self.relighter.has_presence() {
            // From the network's crop, not the frame: one pass over the face
            // region feeds both. (The shipped classifier's decisions are the
            // same either way: docs/benchmark.md, "Skipping what a scene does not need".)
            let small = timed(&mut self.counts.crop_seconds, || {
                resample_square(&image, res, PRESENCE_SIZE)
            });
            presence = self.relighter.presence(&small)?;
            if presence.is_some_and(|p| p < self.skips.presence_threshold) {
                self.counts.passed_absent += 1;
                self.reset();
                return Ok(Prepared::Decided(passed(PassThrough::Absent, presence)));
            }
        }
        let average = self.peek_average(&source);
        // Only a known source light can be compared: a predicted one comes from the
        // frame, so it must be predicted afresh each time.
        if self.skips.skip_same_light
            && matches!(source, Source::Known(_))
            && let (Some(avg), Some(target)) = (&average, self.target())
            && avg.distance(target) <= self.skips.same_light_tolerance
        {
            self.counts.passed_same_light += 1;
            self.skip_frame(&source);
            return Ok(Prepared::Decided(Outcome {
                predicted: self.last.as_ref().and_then(|l| l.predicted.clone()),
                ..passed(PassThrough::SameLight, presence)
            }));
        }
        let last = self.last.as_ref().filter(|last| last.crop.near(crop));
        let change_since_network = last.map_or(f32::INFINITY, |l| mean_abs_diff(&image, &l.image));
        let reuse = last.and_then(|last| {
            if late {
                return Some(Reuse::Late);
            }
            let light_change = average
                .as_ref()
                .map_or(f32::INFINITY, |a| a.distance(&last.average));
            (last.carried + 1 < self.skips.reuse_interval
                && change_since_network <= self.skips.reuse_threshold
                && light_change <= self.skips.reuse_light_threshold)
                .then_some(Reuse::Interval)
        });
        if let Some(why) = reuse {
            match why {
                Reuse::Late => self.counts.reused_late += 1,
                Reuse::Interval => self.counts.reused_interval += 1,
            }
            self.skip_frame(&source);
            let last = self.last.as_mut().expect("reuse needs a relit frame");
            last.carried += 1;
            // The last lighting change, carried onto this frame as it is
            // ([`FramePolicy::decided`]): a smooth gain of the frame's own
            // pixels, so it follows the frame's detail and costs nothing to
            // carry (building a new one costs more than the paste).
            return Ok(Prepared::Decided(Outcome {
                action: Action::Reused(why),
                change: None,
                strength,
                predicted: last.predicted.clone(),
                luma,
                presence,
                change_since_network,
            }));
        }
        Ok(Prepared::Relight(Pending {
            image,
            crop,
            face,
            source,
            want_prediction,
            average,
            so_far: Outcome {
                action: Action::Relit,
                change: None,
                strength,
                predicted: None,
                luma,
                presence,
                change_since_network,
            },
        }))
    }

    /// A decision of [`FramePolicy::prepare`] as an outcome: a frame that
    /// carries the last change gets it.
    pub fn decided(&self, decided: Outcome<'static>) -> Outcome<'_> {
        let carried = matches!(decided.action, Action::Reused(_));
        Outcome {
            change: carried.then(|| {
                &self
                    .last
                    .as_ref()
                    .expect("reuse needs a relit frame")
                    .change
            }),
            ..decided
        }
    }

    /// [`FramePolicy::finish`], with `meanwhile` run on another thread while
    /// the network runs on this one: work on the frame that does not need
    /// the network's result (the denoising), which the other core does
    /// instead of waiting. Returns the outcome, what `meanwhile` returned and
    /// the seconds this thread then waited for it.
    pub fn finish_while<T: Send>(
        &mut self,
        pending: Pending,
        meanwhile: impl FnOnce() -> T + Send,
    ) -> (Result<Outcome<'_>, EngineError>, T, f64) {
        let (done, (outcome, finished)) =
            beside_long(meanwhile, || (self.finish(pending), Instant::now()));
        (outcome, done, finished.elapsed().as_secs_f64())
    }

    /// The second half of [`FramePolicy::process`]: runs the network on what
    /// [`FramePolicy::prepare`] read, and builds the lighting change.
    pub fn finish(&mut self, pending: Pending) -> Result<Outcome<'_>, EngineError> {
        let Pending {
            image,
            crop,
            face,
            source,
            want_prediction,
            average,
            so_far,
        } = pending;
        let res = self.relighter.resolution();
        self.spread_colour.follow_face(crop);
        let out = self.relight(&image, face, source, want_prediction)?;
        let Some(relit) = out.relit else {
            return Ok(Outcome {
                action: Action::PassedThrough(PassThrough::NonFinite),
                predicted: out.predicted,
                change_since_network: 0.0,
                ..so_far
            });
        };
        self.counts.relit += 1;
        let change = timed(&mut self.counts.change_seconds, || {
            LightingChange::new(&image, &relit, res, face)
        });
        let last = self.last.insert(Processed {
            image,
            average: average.unwrap_or(out.source),
            change,
            crop,
            predicted: out.predicted.clone(),
            carried: 0,
        });
        Ok(Outcome {
            change: Some(&last.change),
            predicted: out.predicted,
            ..so_far
        })
    }

    /// Runs the network on one image (planar sRGB in [0, 1], 3 × R × R, the face
    /// at `face`) with the stream's temporal filters. The light decoder runs when the
    /// source is unknown or `want_prediction`. A NaN or Inf anywhere resets the
    /// temporal state.
    pub fn relight(
        &mut self,
        image: &[f32],
        face: FacePlace,
        source: Source,
        want_prediction: bool,
    ) -> Result<FrameOutput, EngineError> {
        if self.target.is_none() {
            return Err(EngineError::Inference("no target light is set".into()));
        }
        let encoded = self.relighter.encode(image)?;
        let predicted = if want_prediction || source == Source::Unknown {
            self.counts.predictions += 1;
            let decoded = self.relighter.predict_light(&encoded)?;
            Some(if self.temporal.colour_tracking {
                let res = self.relighter.resolution();
                self.colours.push(face_colour(image, res, face), decoded)
            } else {
                decoded
            })
        } else {
            None
        };
        let known = matches!(source, Source::Known(_));
        let this_source = match source {
            Source::Known(l) => l,
            Source::Unknown => predicted.clone().expect("predicted above"),
        };
        if !this_source.is_finite() {
            // A broken prediction must neither light this frame nor enter the average.
            return Ok(self.non_finite(predicted, this_source));
        }
        let this_source = if known {
            this_source
        } else {
            self.predictions.push(this_source)
        };
        self.last_source = Some(this_source.clone());
        let averaged = timed(&mut self.counts.filter_seconds, || {
            self.averager.push(this_source)
        });
        self.spread_colour.follow_source(&averaged);
        // A still screen gives the same averaged light frame after frame: its code is kept.
        if self
            .source_code
            .as_ref()
            .is_none_or(|(light, _)| *light != averaged)
        {
            let code = self.relighter.encode_light(&averaged)?;
            self.counts.source_encodes += 1;
            self.source_code = Some((averaged.clone(), code));
        }
        let (Some((_, source_code)), Some((_, target_code))) = (&self.source_code, &self.target)
        else {
            unreachable!("the source code is set above and the target checked at the start");
        };
        let spread_code = if self.spread_colour_on && self.spread_colour.due() {
            let relighter = &mut self.relighter;
            self.spread_colour
                .code(|light| relighter.encode_light(light))?
        } else {
            None
        };
        let codes: Vec<&[f32]> = std::iter::once(target_code.as_slice())
            .chain(spread_code)
            .collect();
        let (smoother, filter_seconds) = (&mut self.smoother, &mut self.counts.filter_seconds);
        let relit = self
            .relighter
            .relight(&encoded, source_code, &codes, |features| {
                timed(filter_seconds, || smoother.smooth(features))
            })?;
        match relit {
            Relit::Images(images) => {
                let mut images = images.into_iter();
                let own = images.next().expect("an image for the target's own code");
                if let Some(spread) = images.next() {
                    self.counts.spread_decodes += 1;
                    self.spread_colour.learn(&own, &spread);
                }
                let relit = if self.spread_colour_on {
                    self.spread_colour.apply(own)
                } else {
                    own
                };
                Ok(FrameOutput {
                    relit: Some(relit),
                    predicted: predicted.filter(Light::is_finite),
                    source: averaged,
                })
            }
            Relit::NonFinite => Ok(self.non_finite(predicted, averaged)),
        }
    }

    /// The output of a frame the model broke on: nothing relit, and the temporal
    /// state starts afresh with the next frame.
    fn non_finite(&mut self, predicted: Option<Light>, source: Light) -> FrameOutput {
        self.counts.passed_non_finite += 1;
        self.reset();
        FrameOutput {
            relit: None,
            predicted: predicted.filter(Light::is_finite),
            source,
        }
    }

    /// The source light the frame would be de-lit with, if its own is `source`
    /// (the last frame's own light when unknown), without changing any state.
    fn peek_average(&self, source: &Source) -> Option<Light> {
        let light = match source {
            Source::Known(l) => l.clone(),
            Source::Unknown => self.last_source.clone()?,
        };
        Some(self.averager.clone().push(light))
    }

    /// Accounts for a frame that did not run the network: its source light joins
    /// the average, and the smoothed features advance as if the last frame's had
    /// been seen again, which is what a static scene gives.
    fn skip_frame(&mut self, source: &Source) {
        let light = match source {
            Source::Known(l) => Some(l.clone()),
            Source::Unknown => self.last_source.clone(),
        };
        if let Some(l) = light {
            self.averager.push(l);
        }
        self.smoother.repeat_last();
    }
}
