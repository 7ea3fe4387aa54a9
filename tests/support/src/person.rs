//! Frames of the simulated person (`deskstage`'s default subject) and of their
//! monitor, and the network's input made from a frame.

use std::sync::OnceLock;

use deskstage::content::{Clip, Playlist};
use deskstage::material::Look;
use deskstage::math::Vec3;
use deskstage::monitor::{CellLight, RgbImage};
use deskstage::render::{Renderer, Scene, Sensor};
use deskstage::subject::{State, Subject};

/// Size of the test webcam frames.
pub const FACE_W: u32 = 320;
pub const FACE_H: u32 = 240;

/// The default person, frontal, lit by a white monitor: a 320×240 RGB webcam frame.
pub fn face_rgb() -> &'static RgbImage {
    static FACE: OnceLock<RgbImage> = OnceLock::new();
    FACE.get_or_init(|| render_face(Vec3::new(1.0, 1.0, 1.0)))
}

/// The person, frontal, lit by a uniform monitor colour: a 320×240 RGB webcam frame.
pub fn render_face(monitor: Vec3) -> RgbImage {
    render_person(&State::default(), monitor, FACE_W, FACE_H)
}

/// The person in `state` (pose, expression, present or not) lit by a uniform
/// monitor colour, without sensor noise, at any frame size.
pub fn render_person(state: &State, monitor: Vec3, width: u32, height: u32) -> RgbImage {
    let r = Renderer::new(Scene::new(
        Subject::default(),
        width as usize,
        height as usize,
    ))
    .unwrap();
    let t = r.prepare(&Look::default(), state);
    let light = CellLight::uniform(16, 32, monitor);
    Sensor::default().clean(&r.render(&t, &[&light])[0])
}

/// A monitor frame of one colour.
pub fn monitor_rgb(colour: Vec3) -> RgbImage {
    Playlist::still(Clip::Solid(colour)).frame(0.0)
}

/// The network's input for an RGB image: its centred full-height square at `res`.
pub fn network_input(img: &RgbImage, res: usize) -> Vec<f32> {
    use gstlsydrelight::frame::{Crop, Frame, sample_crop};
    let frame = Frame::packed_rgb(&img.data, img.width, img.height);
    sample_crop(
        &frame,
        Crop::centred(img.width, img.height, 0.5, 0.5, 1.0),
        res,
    )
}
