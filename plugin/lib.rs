//! # lsydrelight
//!
//! A GStreamer plugin that relights a person's face in video, in real time,
//! with a network personalised to that person: "Personalized Video Relighting
//! With an At-Home Light Stage" (Choi, Christman, Sengupta, ECCV 2024).
//!
//! - [`lsydrelight`]: the element.
//! - [`engine`]: the model contract, ONNX Runtime and the stateful relighter.
//! - [`frame`], [`light`]: pixels in and out, and monitor frames as lights.
//! - [`monitor_match`]: whether the light on a face follows the screen it faces.
//! - [`paths`]: where the default model and ONNX Runtime are found.
//! - [`targets`]: target-light presets, environment maps and crossfades.

pub mod engine;
pub mod face;
pub mod frame;
pub mod light;
pub mod lsydrelight;
pub mod monitor_match;
pub mod parallel;
pub mod paths;
pub mod targets;

fn plugin_init(plugin: &gst::Plugin) -> Result<(), glib::BoolError> {
    paths::set_plugin_file(plugin.filename());
    lsydrelight::register(plugin)
}

gst::plugin_define!(
    lsydrelight,
    env!("CARGO_PKG_DESCRIPTION"),
    plugin_init,
    concat!(env!("CARGO_PKG_VERSION"), "-", env!("COMMIT_ID")),
    "MPL-2.0",
    env!("CARGO_PKG_NAME"),
    env!("CARGO_PKG_NAME"),
    env!("CARGO_PKG_REPOSITORY"),
    env!("BUILD_REL_DATE")
);
