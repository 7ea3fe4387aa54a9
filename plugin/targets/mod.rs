//! Target lights beyond a PNG of monitor content: built-in presets, environment
//! maps seen through a monitor-shaped window, and the crossfade between targets.
//! Nothing here knows GStreamer; the element wires it to its properties.

pub mod crossfade;
pub mod panorama;
pub mod presets;

pub use crossfade::Crossfade;
pub use panorama::{Panorama, View};
pub use presets::Preset;
