//! # lsydrelight
//!
//! Relights the face in a video to a target monitor light, with a network
//! personalised to the person ("Personalized Video Relighting With an
//! At-Home Light Stage", Choi, Christman, Sengupta, ECCV 2024).
//!
//! Pads:
//! - `sink`: the face video (I420, NV12, Y444, RGBA, BGRA, RGBx, BGRx, RGB, BGR; any size and rate).
//! - `monitor_sink` (request): what the monitor showed, e.g. a screen capture, any size and rate.
//!   Each face frame uses the monitor frame shown at its running time minus `monitor-offset`.
//!   A frame's light is computed on the monitor stream's own thread as it arrives (while that
//!   stream runs no faster than the face's; faster, only for the frames used, on the
//!   element's thread).
//!   Without this pad, or while the monitor stream is stalled or over, the source light is
//!   predicted from the face (unknown-source mode).
//! - `target_sink` (request): a video whose frames are the target light (monitor content,
//!   e.g. the virtual background the person appears in front of), aligned by running time
//!   as `monitor_sink` is, and its lights computed alike; while it has not
//!   started the target properties hold, and when it stalls or ends its last frame stays
//!   the target (one warning says so).
//! - `src`: the relit video, in the face video's caps. A frame relit with the monitor's
//!   light carries a `GstReferenceTimestampMeta` with caps `timestamp/x-lsydrelight-monitor`
//!   holding that monitor frame's running time.
//! - `monitor_src`: the predicted source monitor light as a small RGB video at the face
//!   frame rate; computed only while linked.
//!
//! With `match-check` on and a monitor stream, the element checks that the light on the
//! face follows the screen (the paper's section 4.3, against replayed or synthesised
//! faces) and posts an element message `lsydrelight-monitor-match` about once a second
//! with the score over `match-window` seconds and its verdict ([`crate::monitor_match`]).
//! The predicted light is a blurred view of the user's screen: it is computed only for
//! a linked `monitor_src`, the check, or when the source light is unknown.
//!
//! The face is followed with a face detector (`face-tracking`), and the square the
//! model's crop rule gives around it is relit; with no face the frame passes. A
//! dark face region (black frames, fades) passes too.
//!
//! A relit frame carries a `GstVideoRegionOfInterestMeta` of type `face` naming that
//! square, with a parameter structure `lsydrelight` holding how much of the change shows
//! (`strength`, a double in [0, 1]: less while a face fades in or out), the fade's
//! width beyond the head and shoulders it covers whole (`feather`, an unsigned int, in
//! pixels) and the
//! face in the square (`face-x`, `face-y`: ints; `face-size`, an unsigned int: one face
//! height square about the face's centre, which sits higher in the square when the square
//! was moved down to stay inside the frame), so that downstream elements and measures know
//! what was changed where.
//!
//! The source light is averaged over the last `average-frames` frames with weights
//! `beta`^i, and the de-lit features are smoothed with `alpha` (the paper's section 3.3).
//!
//! ## Example pipelines
//!
//! Relight a recorded call (face video and screen recording) offline:
//!
//! ```text
//! gst-launch-1.0 -e lsydrelight name=r target-location=models/targets/sunset.png \
//!     filesrc location=face.y4m ! y4mdec ! r.sink \
//!     filesrc location=monitor.y4m ! y4mdec ! r.monitor_sink \
//!     r.src ! videoconvert ! x264enc ! mp4mux ! filesink location=relit.mp4
//! ```
//!
//! A webcam with the screen it faces, live, plus the predicted monitor:
//!
//! ```text
//! gst-launch-1.0 -e lsydrelight name=r \
//!     v4l2src ! videoconvert ! r.sink \
//!     ximagesrc use-damage=false ! video/x-raw,framerate=10/1 ! videoconvert ! r.monitor_sink \
//!     r.src ! queue ! autovideosink \
//!     r.monitor_src ! queue ! videoscale ! autovideosink
//! ```
//!
//! Targets: a preset (`target-preset=sunset`), an environment map seen through the monitor
//! (`target-environment=room.exr target-fov=180 target-yaw=90 target-exposure=-1`) or a
//! PNG of monitor content (`target-location`), in that order of precedence. A change while
//! playing crossfades over `target-transition`. A virtual background that lights the face:
//!
//! ```text
//! gst-launch-1.0 -e lsydrelight name=r v4l2src ! videoconvert ! r.sink \
//!     filesrc location=background.mp4 ! decodebin ! videoconvert ! r.target_sink \
//!     r.src ! videoconvert ! autovideosink
//! ```
//!
//! A webcam alone (the source light is predicted), to a virtual camera for OBS or calls:
//!
//! ```text
//! gst-launch-1.0 -e v4l2src ! videoconvert ! lsydrelight ! videoconvert ! v4l2sink device=/dev/video10
//! ```

use gst::glib;
use gst::prelude::*;

mod imp;
mod lights;
mod match_check;
mod monitor;
mod process;
mod qos;
mod region;
mod settings;
mod side_stream;
mod state;
mod stats;
mod target;
pub mod video;

pub use imp::MONITOR_TIMESTAMP_CAPS;
/// A mapped video frame as the GStreamer-free frame code sees it, for tools that
/// read frames the way the element does (the capture tool's monitor light).
pub use video::frame_view;

glib::wrapper! {
    pub struct LsydRelight(ObjectSubclass<imp::LsydRelight>) @extends gst_base::Aggregator, gst::Element, gst::Object;
}

/// Where the network runs.
#[derive(Debug, Eq, PartialEq, Ord, PartialOrd, Hash, Clone, Copy, Default, glib::Enum)]
#[repr(u32)]
#[enum_type(name = "GstLsydRelightExecutionProvider")]
pub enum ExecutionProvider {
    #[default]
    #[enum_value(name = "CPU", nick = "cpu")]
    Cpu = 0,
    #[enum_value(name = "CUDA (needs an ONNX Runtime built with CUDA)", nick = "cuda")]
    Cuda = 1,
}

pub fn register(plugin: &gst::Plugin) -> Result<(), glib::BoolError> {
    ExecutionProvider::static_type().mark_as_plugin_api(gst::PluginAPIFlags::empty());
    crate::targets::Preset::static_type().mark_as_plugin_api(gst::PluginAPIFlags::empty());
    gst::Element::register(
        Some(plugin),
        "lsydrelight",
        gst::Rank::NONE,
        LsydRelight::static_type(),
    )
}

/// Locks `m`, taking its data even when a thread panicked while holding it: the
/// panic was caught and reported where it happened, and the element goes on.
fn lock<T>(m: &std::sync::Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}
