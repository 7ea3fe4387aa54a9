//! The network's stage chain: the model's ONNX sessions, run in the order the
//! contract allows. It holds no state from frame to frame; the stream's state
//! (averaged lights, smoothed features, the last relighting) is the per-frame
//! policy's ([`super::policy`]).
//!
//! 1. `encoder`: image → stem and raw features e1..e7 ([`Relighter::encode`]);
//! 2. `light_decoder`: e2, e4, e6 → predicted source light ([`Relighter::predict_light`]);
//! 3. `light_encoder`: a light → its code ([`Relighter::encode_light`]);
//! 4. `delight`: e1..e7 and the source code → de-lit features f1..f7, which the
//!    caller may change in place (the paper smooths them over time);
//! 5. `decoder`: f1..f7, stem and a target code → the relit image, once per
//!    target code asked for ([`Relighter::relight`] runs 4 and 5).

use std::path::Path;
use std::time::Instant;

use ort::environment::Environment;
use ort::session::Session;
use ort::value::{DynValue, TensorRef};

use super::contract::{CODE_DIM, Manifest, PRESENCE_SIZE, RAW, SMOOTHED};
use super::runtime::{EngineError, Provider, Sessions, inference, load_model};
use crate::light::{LIGHT_COLS, LIGHT_LEN, LIGHT_ROWS, Light};

/// A frame through the encoder: what the later stages take.
pub struct Encoded {
    stem: DynValue,
    /// e1..e7.
    raw: Vec<DynValue>,
}

/// What the de-lit features' hook saw.
pub enum Relit {
    /// Planar sRGB in [0, 1], 3 × R × R, one per target code in its order; the
    /// first is finite, the others as decoded.
    Images(Vec<Vec<f32>>),
    /// The de-lit features or the first image held NaN or Inf; the hook was not
    /// called when the features were the broken ones.
    NonFinite,
}

/// Seconds inside ONNX Runtime, every stage, for statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NetworkTime {
    pub seconds: f64,
}

pub struct Relighter {
    manifest: Manifest,
    sessions: Sessions,
    time: NetworkTime,
}

fn tensor<'a>(shape: [usize; 4], data: &'a [f32]) -> Result<TensorRef<'a, f32>, EngineError> {
    TensorRef::from_array_view((shape, data)).map_err(inference)
}

fn tensor_code(code: &[f32]) -> Result<TensorRef<'_, f32>, EngineError> {
    TensorRef::from_array_view(([1usize, CODE_DIM], code)).map_err(inference)
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
pub(crate) fn timed<T>(seconds: &mut f64, body: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let out = body();
    *seconds += start.elapsed().as_secs_f64();
    out
}

impl Relighter {
    pub fn new(
        env: &Environment,
        model: &Path,
        threads: usize,
        provider: Provider,
    ) -> Result<Relighter, EngineError> {
        let (manifest, sessions) = load_model(env, model, threads, provider)?;
        Ok(Relighter {
            manifest,
            sessions,
            time: NetworkTime::default(),
        })
    }

    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Side of the square image the network takes.
    pub fn resolution(&self) -> usize {
        self.manifest.resolution
    }

    pub fn time(&self) -> NetworkTime {
        self.time
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
        let mut out = timed(&mut self.time.seconds, || {
            session.run(ort::inputs!["image" => input])
        })
        .map_err(inference)?;
        let logit = values(&take(&mut out, "presence")?)?[0];
        Ok(Some(1.0 / (1.0 + (-logit).exp())))
    }

    /// The code of a light.
    pub fn encode_light(&mut self, light: &Light) -> Result<Vec<f32>, EngineError> {
        let session = &mut self.sessions.light_encoder;
        timed(&mut self.time.seconds, || encode_light(session, light))
    }

    /// The encoder: `image` is planar sRGB in [0, 1], 3 × R × R.
    pub fn encode(&mut self, image: &[f32]) -> Result<Encoded, EngineError> {
        let r = self.manifest.resolution;
        if image.len() != 3 * r * r {
            return Err(EngineError::Inference(format!(
                "image has {} values, not 3x{r}x{r}",
                image.len()
            )));
        }
        let input = tensor([1, 3, r, r], image)?;
        let encoder = &mut self.sessions.encoder;
        let mut out = timed(&mut self.time.seconds, || {
            encoder.run(ort::inputs!["image" => input])
        })
        .map_err(inference)?;
        let stem = take(&mut out, "stem")?;
        let raw = RAW
            .iter()
            .map(|n| take(&mut out, n))
            .collect::<Result<_, _>>()?;
        Ok(Encoded { stem, raw })
    }

    /// The light decoder: the source light predicted from the face.
    pub fn predict_light(&mut self, encoded: &Encoded) -> Result<Light, EngineError> {
        let raw = &encoded.raw;
        let decoder = &mut self.sessions.light_decoder;
        let mut out = timed(&mut self.time.seconds, || {
            decoder.run(ort::inputs!["e2" => &raw[1], "e4" => &raw[3], "e6" => &raw[5]])
        })
        .map_err(inference)?;
        let v = take(&mut out, "predicted_light")?;
        let d = values(&v)?;
        if d.len() != LIGHT_LEN {
            return Err(EngineError::Inference(format!(
                "predicted light has {} values, not {LIGHT_LEN}",
                d.len()
            )));
        }
        Ok(Light(d.to_vec()))
    }

    /// De-lights the encoded frame with `source_code`, lets `features` change the
    /// de-lit features f1..f7 in place (only when they are finite), and decodes them
    /// relit with each of `target_codes`: the first the frame's target, whose
    /// broken image breaks the frame; the others' the caller checks.
    pub fn relight(
        &mut self,
        encoded: &Encoded,
        source_code: &[f32],
        target_codes: &[&[f32]],
        features: impl FnOnce(&mut [&mut [f32]]),
    ) -> Result<Relit, EngineError> {
        let raw = &encoded.raw;
        let source_code = tensor_code(source_code)?;
        let delight = &mut self.sessions.delight;
        let mut delit_out = timed(&mut self.time.seconds, || {
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
            return Ok(Relit::NonFinite);
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
            features(&mut slices);
        }
        let mut images = Vec::with_capacity(target_codes.len());
        for target_code in target_codes {
            let target_code = tensor_code(target_code)?;
            let decoder = &mut self.sessions.decoder;
            let stem = &encoded.stem;
            let mut dec = timed(&mut self.time.seconds, || {
                decoder.run(ort::inputs![
                    "f1" => &delit[0], "f2" => &delit[1], "f3" => &delit[2], "f4" => &delit[3],
                    "f5" => &delit[4], "f6" => &delit[5], "f7" => &delit[6],
                    "stem" => stem,
                    "target_code" => target_code,
                ])
            })
            .map_err(inference)?;
            let relit = values(&take(&mut dec, "relit")?)?.to_vec();
            if images.is_empty() && !relit.iter().all(|v| v.is_finite()) {
                return Ok(Relit::NonFinite);
            }
            images.push(relit);
        }
        Ok(Relit::Images(images))
    }
}

fn encode_light(session: &mut Session, light: &Light) -> Result<Vec<f32>, EngineError> {
    let mut out = session
        .run(ort::inputs!["light" => tensor([1, 3, LIGHT_ROWS, LIGHT_COLS], &light.0)?])
        .map_err(inference)?;
    Ok(values(&take(&mut out, "code")?)?.to_vec())
}
