//! The inference engine, independent of GStreamer: the model contract, ONNX
//! Runtime, the paper's temporal filters and the per-stream relighter.

pub mod contract;
pub mod relighter;
pub mod runtime;
pub mod temporal;

pub use contract::{ContractError, Manifest};
pub use relighter::{EngineCounts, FrameOutput, Relighter, Source, Temporal};
pub use runtime::{EngineError, Provider, environment};
