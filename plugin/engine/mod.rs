//! The inference engine, independent of GStreamer: the model contract, ONNX
//! Runtime, the network's stage chain, the paper's temporal filters and the
//! per-frame policy that decides what each frame of a stream gets.

pub mod colour_tracking;
pub mod contract;
pub mod policy;
pub mod relighter;
pub mod runtime;
pub mod spread_colour;
pub mod temporal;

pub use contract::{ContractError, CropSpec, Manifest};
pub use policy::{
    Action, FrameOutput, FramePolicy, FrameRequest, Outcome, PassThrough, Pending, PolicyCounts,
    Prepared, Reuse, Skips, Source,
};
pub use relighter::Relighter;
pub use runtime::{EngineError, Provider, environment};
pub use temporal::Temporal;
