//! ONNX Runtime: the one process-wide environment, and the model's sessions.
//!
//! ONNX Runtime comes from the pinned PyPI wheel's shared library, loaded at
//! run time (`ort`'s `load-dynamic`). Only one environment may exist per
//! process, ever, so every element instance shares it; the library path of
//! the first instance wins and a different path later is an error.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use ort::environment::Environment;
use ort::session::Session;
use ort::session::builder::{GraphOptimizationLevel, SessionBuilder};
use ort::value::{TensorElementType, ValueType};

use super::contract::{ContractError, Manifest, PRESENCE_STAGE, STAGES, StageSpec, TensorSpec};

/// Which hardware runs the network.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Provider {
    #[default]
    Cpu,
    Cuda,
}

/// Why the engine cannot run.
#[derive(Clone, Debug, PartialEq)]
pub enum EngineError {
    /// The ONNX Runtime library is missing or cannot be loaded.
    Library(String),
    Model(ContractError),
    /// The requested execution provider cannot start.
    Provider(String),
    Inference(String),
}

impl fmt::Display for EngineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EngineError::Library(e) | EngineError::Provider(e) | EngineError::Inference(e) => {
                f.write_str(e)
            }
            EngineError::Model(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for EngineError {}

impl From<ContractError> for EngineError {
    fn from(e: ContractError) -> Self {
        EngineError::Model(e)
    }
}

pub(crate) fn inference(e: impl fmt::Display) -> EngineError {
    EngineError::Inference(format!("ONNX Runtime failed: {e}"))
}

struct Loaded {
    library: PathBuf,
    environment: Environment,
}

static ENVIRONMENT: OnceLock<Loaded> = OnceLock::new();
static INIT: Mutex<()> = Mutex::new(());

/// The process-wide ONNX Runtime environment, loading the library on first use.
pub fn environment(library: &Path) -> Result<&'static Environment, EngineError> {
    let _guard = INIT.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(l) = ENVIRONMENT.get() {
        if l.library != library {
            return Err(EngineError::Library(format!(
                "ONNX Runtime is already loaded in this process from {}; every instance must use the same library, not {}",
                l.library.display(),
                library.display()
            )));
        }
        return Ok(&l.environment);
    }
    // dlopen only says "failed"; say which file and how to get it.
    if !library.is_file() {
        return Err(EngineError::Library(format!(
            "the ONNX Runtime library {} does not exist; run scripts/setup.sh, or point the \
             LSYDRELIGHT_ORT_LIBRARY environment variable (or the ort-library property) at \
             libonnxruntime.so from the onnxruntime 1.31 Python wheel",
            library.display()
        )));
    }
    let builder = ort::init_from(library).map_err(|e| {
        EngineError::Library(format!(
            "cannot load ONNX Runtime from {}: {e}",
            library.display()
        ))
    })?;
    let environment = builder.with_name("lsydrelight").build().map_err(|e| {
        EngineError::Library(format!(
            "cannot start ONNX Runtime from {}: {e}",
            library.display()
        ))
    })?;
    let loaded = ENVIRONMENT.get_or_init(|| Loaded {
        library: library.to_path_buf(),
        environment,
    });
    Ok(&loaded.environment)
}

/// The stage sessions of a model.
pub struct Sessions {
    pub light_encoder: Session,
    pub encoder: Session,
    pub light_decoder: Session,
    pub delight: Session,
    pub decoder: Session,
    /// The optional presence classifier.
    pub presence: Option<Session>,
}

/// Loads and checks a model folder: the manifest, then every session against it.
pub fn load_model(
    env: &Environment,
    dir: &Path,
    threads: usize,
    provider: Provider,
) -> Result<(Manifest, Sessions), EngineError> {
    let manifest = Manifest::load(dir)?;
    let mut sessions = Vec::with_capacity(STAGES.len());
    for name in STAGES {
        let spec = &manifest.stages[name];
        let session = open_session(env, &dir.join(&spec.file), threads, provider)?;
        check_session(name, spec, &session)?;
        sessions.push(session);
    }
    let presence = match manifest.stages.get(PRESENCE_STAGE) {
        Some(spec) => {
            let session = open_session(env, &dir.join(&spec.file), 1, Provider::Cpu)?;
            check_session(PRESENCE_STAGE, spec, &session)?;
            Some(session)
        }
        None => None,
    };
    let mut it = sessions.into_iter();
    let mut next = || it.next().expect("one session per stage");
    Ok((
        manifest,
        Sessions {
            light_encoder: next(),
            encoder: next(),
            light_decoder: next(),
            delight: next(),
            decoder: next(),
            presence,
        },
    ))
}

/// A session builder with the settings every session of the element shares: full
/// graph optimisation, `threads` intra-op threads, and no spinning, because the
/// sessions run one after another (the stages, the presence check, the face
/// detector) and a spinning pool would starve the next one.
pub(crate) fn session_builder(env: &Environment, threads: usize) -> ort::Result<SessionBuilder> {
    Session::builder(env)
        .and_then(|b| {
            b.with_optimization_level(GraphOptimizationLevel::Level3)
                .map_err(Into::into)
        })
        .and_then(|b| b.with_intra_threads(threads.max(1)).map_err(Into::into))
        .and_then(|b| b.with_inter_threads(1).map_err(Into::into))
        .and_then(|b| b.with_intra_op_spinning(false).map_err(Into::into))
}

fn open_session(
    env: &Environment,
    path: &Path,
    threads: usize,
    provider: Provider,
) -> Result<Session, EngineError> {
    let fail = |e: &dyn fmt::Display| {
        EngineError::Model(ContractError::Unreadable(path.to_path_buf(), e.to_string()))
    };
    let mut builder = session_builder(env, threads).map_err(|e| fail(&e))?;
    if provider == Provider::Cuda {
        builder = builder
            .with_execution_providers([ort::ep::CUDA::default().build().error_on_failure()])
            .map_err(|e| {
                EngineError::Provider(format!(
                    "the CUDA execution provider cannot start ({e}); the pinned onnxruntime wheel is CPU-only: \
                     install onnxruntime-gpu 1.31 with CUDA 13 and point LSYDRELIGHT_ORT_LIBRARY at its \
                     library, or set execution-provider=cpu"
                ))
            })?;
    }
    builder.commit_from_file(path).map_err(|e| fail(&e))
}

/// The session's inputs and outputs must be exactly the manifest's.
fn check_session(stage: &str, spec: &StageSpec, session: &Session) -> Result<(), EngineError> {
    let describe = |o: &ort::value::Outlet| -> TensorSpec {
        match o.dtype() {
            ValueType::Tensor { ty, shape, .. } => TensorSpec {
                name: o.name().to_string(),
                shape: shape.to_vec(),
                dtype: match ty {
                    TensorElementType::Float32 => "float32".into(),
                    other => other.to_string(),
                },
            },
            other => TensorSpec {
                name: o.name().to_string(),
                shape: vec![],
                dtype: format!("{other:?}"),
            },
        }
    };
    for (kind, outlets, want) in [
        ("input", session.inputs(), &spec.inputs),
        ("output", session.outputs(), &spec.outputs),
    ] {
        let got: Vec<TensorSpec> = outlets.iter().map(describe).collect();
        let same = got.len() == want.len()
            && got
                .iter()
                .zip(want.iter())
                .all(|(g, w)| g.name == w.name && g.shape == w.shape && g.dtype == w.dtype);
        if !same {
            return Err(EngineError::Model(ContractError::Mismatch(format!(
                "{}'s {kind}s are {:?}, the manifest says {:?}",
                stage,
                got.iter()
                    .map(|t| (&t.name, &t.shape, &t.dtype))
                    .collect::<Vec<_>>(),
                want.iter()
                    .map(|t| (&t.name, &t.shape, &t.dtype))
                    .collect::<Vec<_>>()
            ))));
        }
    }
    Ok(())
}
