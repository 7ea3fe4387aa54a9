//! GStreamer elements of the deskstage simulator.
//!
//! - [`deskstagecam`]: a simulated webcam. It takes the screen video on its
//!   sink pad and outputs what a webcam on that screen films: a simulated
//!   person lit by exactly that content and by the room, moving naturally.
//!
//! The rendering is the `deskstage` crate's ([`deskstage::webcam`]); the
//! element only moves frames between pads. `lsydrelight capture` registers it
//! statically; as a plugin file (`libgstdeskstage.so`) gst-launch finds it too.

pub mod deskstagecam;

fn plugin_init(plugin: &gst::Plugin) -> Result<(), gst::glib::BoolError> {
    deskstagecam::register(plugin)
}

gst::plugin_define!(
    deskstage,
    env!("CARGO_PKG_DESCRIPTION"),
    plugin_init,
    env!("CARGO_PKG_VERSION"),
    "MPL-2.0",
    env!("CARGO_PKG_NAME"),
    env!("CARGO_PKG_NAME"),
    env!("CARGO_PKG_REPOSITORY")
);
