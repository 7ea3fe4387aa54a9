//! The stateful relighting engine: one per video stream.
//!
//! Per frame it runs the model's stages in the order the contract allows:
//!
//! 1. `encoder`: image → stem and raw features e1..e7;
//! 2. `light_decoder` (only when the source light is unknown or a prediction
//!    is wanted): e2, e4, e6 → predicted source light;
//! 3. the source light is averaged over the last N frames and encoded by
//!    `light_encoder`;
//! 4. `delight`: e1..e7 and the source code → de-lit features f1..f7,
//!    which are smoothed with the previous frame's;
//! 5. `decoder`: f1..f7, stem and the target code → the relit image.
//!
//! The target light's code is computed once per target, not per frame.

use std::path::Path;
use std::time::Instant;

use ort::environment::Environment;
use ort::session::Session;
use ort::value::{DynValue, TensorRef};

use super::contract::{CODE_DIM, Manifest, PRESENCE_SIZE, RAW, SMOOTHED};
use super::runtime::{EngineError, Provider, Sessions, inference, load_model};
use super::temporal::{FeatureSmoother, SourceLightAverager};
use crate::light::{LIGHT_COLS, LIGHT_LEN, LIGHT_ROWS, Light};

/// Parameters of the paper's temporal filters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Temporal {
    /// Feature smoothing α; 1 turns smoothing off.
    pub alpha: f32,
    /// Source-light averaging β and frame count N; N = 1 turns averaging off.
    pub beta: f32,
    pub average_frames: usize,
}

impl Default for Temporal {
    fn default() -> Self {
        Temporal {
            alpha: super::temporal::DEFAULT_ALPHA,
            beta: super::temporal::DEFAULT_BETA,
            average_frames: super::temporal::DEFAULT_AVERAGE_FRAMES,
        }
    }
}

/// Where this frame's source light comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// The monitor's content at the frame's time.
    Known(Light),
    /// Nothing is known: the network predicts it (unknown-source mode).
    Unknown,
}

/// The result of one frame.
#[derive(Clone, Debug)]
pub struct FrameOutput {
    /// Planar sRGB in [0, 1], 3 × R × R; None when the model produced NaN or Inf.
    pub relit: Option<Vec<f32>>,
    /// The predicted source monitor light, when it was computed.
    pub predicted: Option<Light>,
    /// The (averaged) source light the frame was de-lit with.
    pub source: Light,
}

/// Work done, for statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EngineCounts {
    pub target_encodes: u64,
    pub predictions: u64,
    pub non_finite: u64,
    /// Seconds inside ONNX Runtime, every stage.
    pub network_seconds: f64,
    /// Seconds spent averaging source lights and smoothing features.
    pub filter_seconds: f64,
}

pub struct Relighter {
    manifest: Manifest,
    sessions: Sessions,
    averager: SourceLightAverager,
    smoother: FeatureSmoother,
    target: Option<(Light, Vec<f32>)>,
    /// The source light of the last frame that ran the network, before averaging.
    last_source: Option<Light>,
    counts: EngineCounts,
}

fn tensor<'a>(shape: [usize; 4], data: &'a [f32]) -> Result<TensorRef<'a, f32>, EngineError> {
    TensorRef::from_array_view((shape, data)).map_err(inference)
}

fn take(outputs: &mut ort::session::SessionOutputs, name: &str) -> Result<DynValue, EngineError> {
    outputs
        .remove(name)
        .ok_or_else(|| EngineError::Inference(format!("the model gave no output {name:?}")))
}

fn values(v: &DynValue) -> Result<&[f32], EngineError> {
    v.try_extract_tensor::<f32>()
        .map(|(_, d)| d)
        .map_err(inference)
}

/// Runs `body`, adding its wall time to `seconds`.
fn timed<T>(seconds: &mut f64, body: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let out = body();
    *seconds += start.elapsed().as_secs_f64();
    out
}

fn light_of(v: &DynValue) -> Result<Light, EngineError> {
    let d = values(v)?;
    if d.len() != LIGHT_LEN {
        return Err(EngineError::Inference(format!(
            "predicted light has {} values, not {LIGHT_LEN}",
            d.len()
        )));
    }
    Ok(Light(d.to_vec()))
}

impl Relighter {
    pub fn new(
        env: &Environment,
        model: &Path,
        threads: usize,
        provider: Provider,
        temporal: Temporal,
    ) -> Result<Relighter, EngineError> {
        let (manifest, sessions) = load_model(env, model, threads, provider)?;
        Ok(Relighter {
            manifest,
            sessions,
            averager: SourceLightAverager::new(temporal.beta, temporal.average_frames),
            smoother: FeatureSmoother::new(temporal.alpha),
            target: None,
            last_source: None,
            counts: EngineCounts::default(),
        })
    }

    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Side of the square image the network takes.
    pub fn resolution(&self) -> usize {
        self.manifest.resolution
    }

    pub fn counts(&self) -> EngineCounts {
        self.counts
    }

    /// Forgets everything learnt from past frames: averaged lights and smoothed features.
    pub fn reset(&mut self) {
        self.averager.reset();
        self.smoother.reset();
        self.last_source = None;
    }

    /// The target light, if one is set.
    pub fn target(&self) -> Option<&Light> {
        self.target.as_ref().map(|(l, _)| l)
    }

    /// The source light the next frame would be de-lit with, if its own is `source`
    /// (the last frame's own light when unknown), without changing any state.
    pub fn peek_average(&self, source: &Source) -> Option<Light> {
        let light = match source {
            Source::Known(l) => l.clone(),
            Source::Unknown => self.last_source.clone()?,
        };
        Some(self.averager.clone().push(light))
    }

    /// Accounts for a frame whose relighting was reused instead of computed: its
    /// source light joins the average, and the smoothed features advance as if the
    /// last frame's had been seen again, which is what a static scene gives.
    pub fn skip_frame(&mut self, source: &Source) {
        let light = match source {
            Source::Known(l) => Some(l.clone()),
            Source::Unknown => self.last_source.clone(),
        };
        if let Some(l) = light {
            self.averager.push(l);
        }
        self.smoother.repeat_last();
    }

    /// Whether the model can tell if the person is in view.
    pub fn has_presence(&self) -> bool {
        self.sessions.presence.is_some()
    }

    /// Probability that the person is in the face region; `image` is planar sRGB in
    /// [0, 1], 3 × 64 × 64. None when the model has no presence stage.
    pub fn presence(&mut self, image: &[f32]) -> Result<Option<f32>, EngineError> {
        let Some(session) = self.sessions.presence.as_mut() else {
            return Ok(None);
        };
        let input = tensor([1, 3, PRESENCE_SIZE, PRESENCE_SIZE], image)?;
        let mut out = timed(&mut self.counts.network_seconds, || {
            session.run(ort::inputs!["image" => input])
        })
        .map_err(inference)?;
        let logit = values(&take(&mut out, "presence")?)?[0];
        Ok(Some(1.0 / (1.0 + (-logit).exp())))
    }

    /// Changes the temporal filters; their state starts afresh.
    pub fn set_temporal(&mut self, t: Temporal) {
        self.averager = SourceLightAverager::new(t.beta, t.average_frames);
        self.smoother = FeatureSmoother::new(t.alpha);
    }

    /// Whether the next frame will be smoothed with a previous one.
    pub fn has_history(&self) -> bool {
        self.smoother.has_state()
    }

    /// The last frame's de-lit features f1..f7 after smoothing.
    pub fn smoothed_features(&self) -> Option<&[Vec<f32>]> {
        self.smoother.state()
    }

    /// The code of a light.
    pub fn encode_light(&mut self, light: &Light) -> Result<Vec<f32>, EngineError> {
        let session = &mut self.sessions.light_encoder;
        timed(&mut self.counts.network_seconds, || encode(session, light))
    }

    /// Sets the target light; its code is computed here, once, and reused every frame.
    pub fn set_target(&mut self, light: &Light) -> Result<(), EngineError> {
        if self.target.as_ref().is_some_and(|(l, _)| l == light) {
            return Ok(());
        }
        let code = self.encode_light(light)?;
        self.counts.target_encodes += 1;
        self.target = Some((light.clone(), code));
        Ok(())
    }

    /// Relights one frame: `image` is planar sRGB in [0, 1], 3 × R × R.
    /// The light decoder runs when the source is unknown or `want_prediction`.
    pub fn process(
        &mut self,
        image: &[f32],
        source: Source,
        want_prediction: bool,
    ) -> Result<FrameOutput, EngineError> {
        let r = self.manifest.resolution;
        if image.len() != 3 * r * r {
            return Err(EngineError::Inference(format!(
                "image has {} values, not 3x{r}x{r}",
                image.len()
            )));
        }
        let target_code = match &self.target {
            Some((_, code)) => code.clone(),
            None => return Err(EngineError::Inference("no target light is set".into())),
        };
        let network = &mut self.counts.network_seconds;
        let input = tensor([1, 3, r, r], image)?;
        let encoder = &mut self.sessions.encoder;
        let mut enc =
            timed(network, || encoder.run(ort::inputs!["image" => input])).map_err(inference)?;
        let stem = take(&mut enc, "stem")?;
        let raw: Vec<DynValue> = RAW
            .iter()
            .map(|n| take(&mut enc, n))
            .collect::<Result<_, _>>()?;
        drop(enc);

        let predicted = if want_prediction || source == Source::Unknown {
            self.counts.predictions += 1;
            let decoder = &mut self.sessions.light_decoder;
            let mut out = timed(network, || {
                decoder.run(ort::inputs!["e2" => &raw[1], "e4" => &raw[3], "e6" => &raw[5]])
            })
            .map_err(inference)?;
            Some(light_of(&take(&mut out, "predicted_light")?)?)
        } else {
            None
        };
        let this_source = match source {
            Source::Known(l) => l,
            Source::Unknown => predicted.clone().expect("predicted above"),
        };
        if !this_source.is_finite() {
            // A broken prediction must neither light this frame nor enter the average.
            return Ok(self.non_finite(predicted, this_source));
        }
        self.last_source = Some(this_source.clone());
        let averaged = timed(&mut self.counts.filter_seconds, || {
            self.averager.push(this_source)
        });
        let network = &mut self.counts.network_seconds;
        let light_encoder = &mut self.sessions.light_encoder;
        let source_code = timed(network, || encode(light_encoder, &averaged))?;

        let source_code = tensor_code(&source_code)?;
        let delight = &mut self.sessions.delight;
        let mut delit_out = timed(network, || {
            delight.run(ort::inputs![
                "e1" => &raw[0], "e2" => &raw[1], "e3" => &raw[2], "e4" => &raw[3],
                "e5" => &raw[4], "e6" => &raw[5], "e7" => &raw[6],
                "source_code" => source_code,
            ])
        })
        .map_err(inference)?;
        let mut delit: Vec<DynValue> = SMOOTHED
            .iter()
            .map(|n| take(&mut delit_out, n))
            .collect::<Result<_, _>>()?;
        drop(delit_out);

        let finite = delit
            .iter()
            .all(|v| values(v).is_ok_and(|d| d.iter().all(|x| x.is_finite())));
        if !finite {
            // Keep NaN out of the smoothing state.
            return Ok(self.non_finite(predicted, averaged));
        }
        {
            let mut slices: Vec<&mut [f32]> = delit
                .iter_mut()
                .map(|v| {
                    v.try_extract_tensor_mut::<f32>()
                        .map(|(_, d)| d)
                        .map_err(inference)
                })
                .collect::<Result<_, _>>()?;
            let smoother = &mut self.smoother;
            timed(&mut self.counts.filter_seconds, || {
                smoother.smooth(&mut slices)
            });
        }

        let target_code = tensor_code(&target_code)?;
        let decoder = &mut self.sessions.decoder;
        let mut dec = timed(&mut self.counts.network_seconds, || {
            decoder.run(ort::inputs![
                "f1" => &delit[0], "f2" => &delit[1], "f3" => &delit[2], "f4" => &delit[3],
                "f5" => &delit[4], "f6" => &delit[5], "f7" => &delit[6],
                "stem" => &stem,
                "target_code" => target_code,
            ])
        })
        .map_err(inference)?;
        let relit = values(&take(&mut dec, "relit")?)?.to_vec();
        drop(dec);
        if !relit.iter().all(|v| v.is_finite()) {
            return Ok(self.non_finite(predicted, averaged));
        }
        Ok(FrameOutput {
            relit: Some(relit),
            predicted: predicted.filter(Light::is_finite),
            source: averaged,
        })
    }

    /// The output of a frame the model broke on (NaN or Inf): nothing relit, and
    /// the temporal state starts afresh with the next frame.
    fn non_finite(&mut self, predicted: Option<Light>, source: Light) -> FrameOutput {
        self.counts.non_finite += 1;
        self.reset();
        FrameOutput {
            relit: None,
            predicted: predicted.filter(Light::is_finite),
            source,
        }
    }
}

fn tensor_code(code: &[f32]) -> Result<TensorRef<'_, f32>, EngineError> {
    TensorRef::from_array_view(([1usize, CODE_DIM], code)).map_err(inference)
}

fn encode(session: &mut Session, light: &Light) -> Result<Vec<f32>, EngineError> {
    let mut out = session
        .run(ort::inputs!["light" => tensor([1, 3, LIGHT_ROWS, LIGHT_COLS], &light.0)?])
        .map_err(inference)?;
    Ok(values(&take(&mut out, "code")?)?.to_vec())
}
