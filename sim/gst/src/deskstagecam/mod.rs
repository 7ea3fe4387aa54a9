//! # deskstagecam
//!
//! A simulated webcam on a desk light stage: it takes what the monitor shows
//! on its sink pad and outputs the camera video of a simulated person sitting
//! in front of that monitor, lit by exactly that content plus a room light,
//! with natural head motion, talking and blinking (the `deskstage` simulator).
//!
//! Pads:
//! - `sink`: the screen video, packed 8-bit RGB (RGB, BGR, RGBx, BGRx, xRGB,
//!   xBGR, RGBA, BGRA, ARGB, ABGR), any size and rate.
//! - `src`: the camera video, RGB at `width` x `height`, at most `fps` frames a
//!   second: a screen frame arriving less than 1/`fps` s after the last filmed
//!   one is dropped. Each camera frame keeps the timestamp of the screen frame
//!   that lit it, and its time in the capture (its running time) sets the pose.
//!
//! Properties set how the person behaves: `subject` (who), `seed` (their motion,
//! outfit and room), `room-light` (above 1 the room overpowers the monitor),
//! `motion` (`natural` or `frozen`) and `away-after` (seconds until they leave
//! the frame). They are read when the caps are set.
//!
//! ## Example pipelines
//!
//! Film the simulated person watching a test pattern:
//!
//! ```text
//! gst-launch-1.0 videotestsrc pattern=ball num-buffers=60 ! videoconvert ! \
//!     deskstagecam subject=201 ! videoconvert ! autovideosink
//! ```
//!
//! As the camera of `lsydrelight capture`, filming whatever the screen branch
//! (the tee named `screen`) shows:
//!
//! ```text
//! lsydrelight capture --out me --camera "screen. ! queue ! deskstagecam subject=201"
//! ```

use gst::glib;
use gst::prelude::*;

mod imp;
mod settings;

glib::wrapper! {
    pub struct DeskstageCam(ObjectSubclass<imp::DeskstageCam>)
        @extends gst_video::VideoFilter, gst_base::BaseTransform, gst::Element, gst::Object;
}

/// How the simulated person moves.
#[derive(Debug, Eq, PartialEq, Hash, Clone, Copy, Default, glib::Enum)]
#[repr(u32)]
#[enum_type(name = "GstDeskstageCamMotion")]
pub enum Motion {
    #[default]
    #[enum_value(
        name = "Natural: head turns, talking, smiling, blinking",
        nick = "natural"
    )]
    Natural = 0,
    #[enum_value(name = "Frozen: one pose and expression throughout", nick = "frozen")]
    Frozen = 1,
}

pub fn register(plugin: &gst::Plugin) -> Result<(), glib::BoolError> {
    Motion::static_type().mark_as_plugin_api(gst::PluginAPIFlags::empty());
    gst::Element::register(
        Some(plugin),
        "deskstagecam",
        gst::Rank::NONE,
        DeskstageCam::static_type(),
    )
}
