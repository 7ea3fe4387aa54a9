//! Helpers shared by lsydrelight's tests (`tests/`) and examples (`examples/`),
//! a dev-dependency of the plugin crate:
//!
//! - [`person`]: frames of the simulated person and their monitor, and the
//!   network's input made from them;
//! - [`video`]: caps and buffers of those frames in every format the element
//!   takes, and back;
//! - [`element`]: the element, and reading what it reports;
//! - [`recording`]: a simulator recording run through the element and scored
//!   against its exact ground truth;
//! - [`quality`]: measures of the output that need no ground truth (box edges,
//!   mottling, pumping), for real footage;
//! - [`direction`]: how strong a relighting is over a face and which way
//!   its light falls, with no ground truth;
//! - [`footage`]: real clips and the simulator's recordings decoded to RGB, and
//!   relit by the element with no monitor stream, for those measures;
//! - [`scorecard`]: those measures on real clips and recordings, as the report
//!   `examples/real_footage` prints and `examples/benchmark --quality` writes;
//! - [`flow`]: classical optical flow, and TecoGAN's tOF built on it;
//!
//! The checkout's paths and registering the plugin are here at the top.

use std::path::{Path, PathBuf};

pub mod direction;
pub mod element;
pub mod flow;
pub mod footage;
pub mod oracle;
pub mod person;
pub mod quality;
pub mod recording;
pub mod scorecard;
pub mod video;

/// Registers the plugin statically (once) so pipelines find `lsydrelight`.
pub fn init() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        gst::init().expect("GStreamer initialises");
        gstlsydrelight::plugin_register_static().expect("the plugin registers");
    });
}

/// The checkout: where the shipped models, targets and `target/` are.
pub fn checkout() -> PathBuf {
    // This crate is `tests/support/` of the checkout.
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .expect("tests/support has two parents")
        .to_path_buf()
}

/// The simulator's default person's own model, `models/default` (the element's
/// default is the starter model, for anyone): the model the tests' person is relit with.
pub fn default_model() -> PathBuf {
    checkout().join("models/default")
}

/// The shipped target light `models/targets/<name>.png`, as the string the
/// element's `target-location` takes.
pub fn target(name: &str) -> String {
    checkout()
        .join(format!("models/targets/{name}.png"))
        .to_string_lossy()
        .into_owned()
}
