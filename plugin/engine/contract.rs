//! The model contract (version 1), read from a model folder's `model.json`.
//!
//! `models/CONTRACT.md` documents it; `train/lsyd/contract.py` writes it.
//! A model that does not match is refused with a message that says what is
//! wrong and what to do.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::light::{LIGHT_COLS, LIGHT_ROWS};

pub const CONTRACT_NAME: &str = "lsydrelight-model";
/// 2: the manifest states the crop rule the network was trained with (`crop`).
pub const CONTRACT_VERSION: u32 = 2;
pub const CODE_DIM: usize = 256;
/// The stages every model has, in the order a frame runs them.
pub const STAGES: [&str; 5] = [
    "light_encoder",
    "encoder",
    "light_decoder",
    "delight",
    "decoder",
];
/// An optional stage: is the person in the face region at all?
pub const PRESENCE_STAGE: &str = "presence";
/// Side of the presence stage's input image.
pub const PRESENCE_SIZE: usize = 64;
/// De-lit features, which are smoothed over time.
pub const SMOOTHED: [&str; 7] = ["f1", "f2", "f3", "f4", "f5", "f6", "f7"];
/// Raw encoder features.
pub const RAW: [&str; 7] = ["e1", "e2", "e3", "e4", "e5", "e6", "e7"];

#[derive(Clone, Debug, Deserialize, PartialEq)]
pub struct TensorSpec {
    pub name: String,
    pub shape: Vec<i64>,
    pub dtype: String,
}

#[derive(Clone, Debug, Deserialize)]
pub struct StageSpec {
    pub file: String,
    pub inputs: Vec<TensorSpec>,
    pub outputs: Vec<TensorSpec>,
}

#[derive(Clone, Debug, Deserialize)]
pub struct ImageSpec {
    pub colour: String,
    pub layout: String,
    pub range: [f32; 2],
}

#[derive(Clone, Debug, Deserialize)]
pub struct LightSpec {
    pub colour: String,
    pub layout: String,
    pub rows: usize,
    pub cols: usize,
}

/// The square the network sees, derived from the face detector's box: `side`
/// face heights square, its centre `lift` face heights above the box's centre.
/// The trainer's crops and the element's follow the same rule.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
pub struct CropSpec {
    pub side: f32,
    pub lift: f32,
}

/// A model's `model.json`.
#[derive(Clone, Debug, Deserialize)]
pub struct Manifest {
    pub contract: String,
    pub version: u32,
    pub name: String,
    pub resolution: usize,
    pub widths: Vec<usize>,
    #[serde(default = "default_precision")]
    pub precision: String,
    pub code_dim: usize,
    pub image: ImageSpec,
    pub light: LightSpec,
    pub smoothed: Vec<String>,
    pub crop: CropSpec,
    pub stages: BTreeMap<String, StageSpec>,
    #[serde(default)]
    pub metrics: serde_json::Value,
}

fn default_precision() -> String {
    "fp32".into()
}

/// Why a model cannot be used.
#[derive(Clone, Debug, PartialEq)]
pub enum ContractError {
    Missing(PathBuf),
    Unreadable(PathBuf, String),
    Mismatch(String),
}

impl fmt::Display for ContractError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ContractError::Missing(p) => write!(
                f,
                "model file {} does not exist; set model-location to a model folder (the shipped ones are models/starter, for anyone, and models/default, for the simulator's person)",
                p.display()
            ),
            ContractError::Unreadable(p, e) => write!(
                f,
                "model file {} cannot be read ({e}); re-export the model with `python -m lsyd.export`",
                p.display()
            ),
            ContractError::Mismatch(e) => write!(
                f,
                "the model does not match the {CONTRACT_NAME} contract version {CONTRACT_VERSION}: {e}; \
                 re-export it with this version of `python -m lsyd.export` (see models/CONTRACT.md)"
            ),
        }
    }
}

impl std::error::Error for ContractError {}

fn mismatch(msg: impl Into<String>) -> ContractError {
    ContractError::Mismatch(msg.into())
}

impl Manifest {
    /// Reads and checks `model.json` in `dir`, and that every stage file exists.
    pub fn load(dir: &Path) -> Result<Manifest, ContractError> {
        let path = dir.join("model.json");
        if !path.exists() {
            return Err(ContractError::Missing(path));
        }
        let text = std::fs::read_to_string(&path)
            .map_err(|e| ContractError::Unreadable(path.clone(), e.to_string()))?;
        let m: Manifest = serde_json::from_str(&text)
            .map_err(|e| ContractError::Unreadable(path.clone(), e.to_string()))?;
        m.check()?;
        for stage in m.stages.values() {
            let file = dir.join(&stage.file);
            if !file.exists() {
                return Err(ContractError::Missing(file));
            }
        }
        Ok(m)
    }

    /// Checks everything the manifest says against the contract.
    pub fn check(&self) -> Result<(), ContractError> {
        if self.contract != CONTRACT_NAME {
            return Err(mismatch(format!(
                "`contract` is {:?}, not {CONTRACT_NAME:?}",
                self.contract
            )));
        }
        if self.version != CONTRACT_VERSION {
            return Err(mismatch(format!(
                "it is version {}, this element reads version {CONTRACT_VERSION}",
                self.version
            )));
        }
        if self.resolution == 0 || !self.resolution.is_multiple_of(16) {
            return Err(mismatch(format!(
                "resolution {} is not a positive multiple of 16",
                self.resolution
            )));
        }
        if self.code_dim != CODE_DIM {
            return Err(mismatch(format!(
                "code_dim is {}, not {CODE_DIM}",
                self.code_dim
            )));
        }
        if self.image.colour != "sRGB"
            || self.image.layout != "NCHW"
            || self.image.range != [0.0, 1.0]
        {
            return Err(mismatch("images must be NCHW sRGB in [0, 1]"));
        }
        if self.light.colour != "linear" || self.light.layout != "NCHW" {
            return Err(mismatch("lights must be NCHW linear RGB"));
        }
        if (self.light.rows, self.light.cols) != (LIGHT_ROWS, LIGHT_COLS) {
            return Err(mismatch(format!(
                "lights are {}x{}, the element computes {LIGHT_ROWS}x{LIGHT_COLS}",
                self.light.rows, self.light.cols
            )));
        }
        if self.smoothed != SMOOTHED {
            return Err(mismatch(format!("smoothed features must be {SMOOTHED:?}")));
        }
        if !(self.crop.side > 0.0 && self.crop.side.is_finite() && self.crop.lift.is_finite()) {
            return Err(mismatch(format!(
                "crop side {} and lift {} must be finite, the side positive",
                self.crop.side, self.crop.lift
            )));
        }
        if self.widths.len() != 5 {
            return Err(mismatch("widths must list five channel counts"));
        }
        let expected = self.expected_stages();
        for name in STAGES {
            let stage = self
                .stages
                .get(name)
                .ok_or_else(|| mismatch(format!("stage {name} is missing")))?;
            let (inputs, outputs) = &expected[name];
            check_tensors(name, "input", &stage.inputs, inputs)?;
            check_tensors(name, "output", &stage.outputs, outputs)?;
        }
        if let Some(stage) = self.stages.get(PRESENCE_STAGE) {
            let (inputs, outputs) = &expected[PRESENCE_STAGE];
            check_tensors(PRESENCE_STAGE, "input", &stage.inputs, inputs)?;
            check_tensors(PRESENCE_STAGE, "output", &stage.outputs, outputs)?;
        }
        if let Some(extra) = self
            .stages
            .keys()
            .find(|k| !STAGES.contains(&k.as_str()) && k.as_str() != PRESENCE_STAGE)
        {
            return Err(mismatch(format!("unknown stage {extra}")));
        }
        Ok(())
    }

    /// Stage tensors implied by resolution and widths.
    fn expected_stages(&self) -> BTreeMap<&'static str, (Vec<TensorSpec>, Vec<TensorSpec>)> {
        let r = self.resolution as i64;
        let w: Vec<i64> = self.widths.iter().map(|&c| c as i64).collect();
        let t = |name: &str, shape: Vec<i64>| TensorSpec {
            name: name.into(),
            shape,
            dtype: "float32".into(),
        };
        let raw_shape = |i: usize| match i {
            0 | 1 => vec![1, w[1], r / 2, r / 2],
            2 | 3 => vec![1, w[2], r / 4, r / 4],
            4 | 5 => vec![1, w[3], r / 8, r / 8],
            _ => vec![1, w[4], r / 16, r / 16],
        };
        let light = vec![1, 3, LIGHT_ROWS as i64, LIGHT_COLS as i64];
        let code = vec![1, CODE_DIM as i64];
        let stem = vec![1, w[0], r, r];
        let raw: Vec<TensorSpec> = (0..7).map(|i| t(RAW[i], raw_shape(i))).collect();
        let delit: Vec<TensorSpec> = (0..7).map(|i| t(SMOOTHED[i], raw_shape(i))).collect();
        let mut m = BTreeMap::new();
        m.insert(
            "light_encoder",
            (
                vec![t("light", light.clone())],
                vec![t("code", code.clone())],
            ),
        );
        let mut enc_out = vec![t("stem", stem.clone())];
        enc_out.extend(raw.clone());
        m.insert("encoder", (vec![t("image", vec![1, 3, r, r])], enc_out));
        m.insert(
            "light_decoder",
            (
                vec![raw[1].clone(), raw[3].clone(), raw[5].clone()],
                vec![t("predicted_light", light)],
            ),
        );
        let mut del_in = raw;
        del_in.push(t("source_code", code.clone()));
        m.insert("delight", (del_in, delit.clone()));
        let mut dec_in = delit;
        dec_in.push(t("stem", stem));
        dec_in.push(t("target_code", code));
        m.insert("decoder", (dec_in, vec![t("relit", vec![1, 3, r, r])]));
        let p = PRESENCE_SIZE as i64;
        m.insert(
            PRESENCE_STAGE,
            (
                vec![t("image", vec![1, 3, p, p])],
                vec![t("presence", vec![1, 1])],
            ),
        );
        m
    }
}

fn check_tensors(
    stage: &str,
    kind: &str,
    got: &[TensorSpec],
    want: &[TensorSpec],
) -> Result<(), ContractError> {
    if got.len() != want.len() {
        return Err(mismatch(format!(
            "stage {stage} has {} {kind}s, expected {}",
            got.len(),
            want.len()
        )));
    }
    for (g, w) in got.iter().zip(want) {
        if g != w {
            return Err(mismatch(format!(
                "stage {stage} {kind} {:?} {:?} {}, expected {:?} {:?} {}",
                g.name, g.shape, g.dtype, w.name, w.shape, w.dtype
            )));
        }
    }
    Ok(())
}
