//! Helpers of the element tests: frames of the synthetic person in any format,
//! monitor frames, and reading what the element reports.

#![allow(dead_code)]

use std::sync::OnceLock;

use deskstage::content::{Clip, Playlist};
use deskstage::material::Look;
use deskstage::math::Vec3;
use deskstage::monitor::{CellLight, RgbImage};
use deskstage::render::{Renderer, Scene, Sensor};
use deskstage::subject::{State, Subject};
use gst::prelude::*;
use gst_video::prelude::*;

#[path = "../../examples/common/mod.rs"]
pub mod common;

#[allow(unused_imports)]
pub use common::{checkout, default_model, init};

pub const FORMATS: [gst_video::VideoFormat; 9] = [
    gst_video::VideoFormat::I420,
    gst_video::VideoFormat::Nv12,
    gst_video::VideoFormat::Y444,
    gst_video::VideoFormat::Rgba,
    gst_video::VideoFormat::Bgra,
    gst_video::VideoFormat::Rgbx,
    gst_video::VideoFormat::Bgrx,
    gst_video::VideoFormat::Rgb,
    gst_video::VideoFormat::Bgr,
];

pub const FACE_W: u32 = 320;
pub const FACE_H: u32 = 240;

/// The default person, frontal, lit by a white monitor: a 320×240 RGB webcam frame.
pub fn face_rgb() -> &'static RgbImage {
    static FACE: OnceLock<RgbImage> = OnceLock::new();
    FACE.get_or_init(|| render_face(Vec3::new(1.0, 1.0, 1.0)))
}

/// The person lit by a uniform monitor colour.
pub fn render_face(monitor: Vec3) -> RgbImage {
    let r = Renderer::new(Scene::new(
        Subject::default(),
        FACE_W as usize,
        FACE_H as usize,
    ))
    .unwrap();
    let t = r.prepare(&Look::default(), &State::default());
    let light = CellLight::uniform(16, 32, monitor);
    Sensor::default().clean(&r.render(&t, &[&light])[0])
}

pub fn rgb_caps(w: u32, h: u32, fps: i32) -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format(gst_video::VideoFormat::Rgb)
        .width(w as i32)
        .height(h as i32)
        .framerate(gst::Fraction::new(fps, 1))
        .build()
}

pub fn caps(format: gst_video::VideoFormat, w: u32, h: u32, fps: i32) -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format(format)
        .width(w as i32)
        .height(h as i32)
        .framerate(gst::Fraction::new(fps, 1))
        .build()
}

fn rgb_buffer(img: &RgbImage) -> gst::Buffer {
    let info = gst_video::VideoInfo::builder(
        gst_video::VideoFormat::Rgb,
        img.width as u32,
        img.height as u32,
    )
    .build()
    .unwrap();
    let mut buffer = gst::Buffer::with_size(info.size()).unwrap();
    {
        let b = buffer.get_mut().unwrap();
        let mut f = gst_video::VideoFrameRef::from_buffer_ref_writable(b, &info).unwrap();
        let stride = f.plane_stride()[0] as usize;
        let data = f.plane_data_mut(0).unwrap();
        for y in 0..img.height {
            data[y * stride..y * stride + img.width * 3]
                .copy_from_slice(&img.data[y * img.width * 3..(y + 1) * img.width * 3]);
        }
    }
    buffer
}

/// A buffer converted by GStreamer's converter from one video format to another.
fn convert(
    buffer: gst::Buffer,
    from: &gst_video::VideoInfo,
    to: &gst_video::VideoInfo,
) -> gst::Buffer {
    let src = gst_video::VideoFrame::from_buffer_readable(buffer, from).unwrap();
    let mut dst =
        gst_video::VideoFrame::from_buffer_writable(gst::Buffer::with_size(to.size()).unwrap(), to)
            .unwrap();
    gst_video::VideoConverter::new(from, to, None)
        .unwrap()
        .frame(&src, &mut dst);
    dst.into_buffer()
}

/// Packed RGB of the same size, rate and colorimetry as `info`.
fn rgb_info(info: &gst_video::VideoInfo) -> gst_video::VideoInfo {
    gst_video::VideoInfo::builder(gst_video::VideoFormat::Rgb, info.width(), info.height())
        .colorimetry(&info.colorimetry())
        .fps(info.fps())
        .build()
        .unwrap()
}

/// An RGB image as a buffer of `caps`, stamped at `pts`.
pub fn buffer(
    img: &RgbImage,
    caps: &gst::Caps,
    pts: gst::ClockTime,
    duration: gst::ClockTime,
) -> gst::Buffer {
    let info = gst_video::VideoInfo::from_caps(caps).unwrap();
    let mut out = convert(rgb_buffer(img), &rgb_info(&info), &info);
    {
        let b = out.get_mut().unwrap();
        b.set_pts(pts);
        b.set_duration(duration);
    }
    out
}

/// A buffer of `caps` as an RGB image.
pub fn to_rgb(buffer: &gst::Buffer, caps: &gst::Caps) -> RgbImage {
    let info = gst_video::VideoInfo::from_caps(caps).unwrap();
    let rgb = rgb_info(&info);
    let f = gst_video::VideoFrame::from_buffer_readable(convert(buffer.clone(), &info, &rgb), &rgb)
        .unwrap();
    let stride = f.plane_stride()[0] as usize;
    let data = f.plane_data(0).unwrap();
    let (w, h) = (info.width() as usize, info.height() as usize);
    let mut img = RgbImage::new(w, h);
    for y in 0..h {
        img.data[y * w * 3..(y + 1) * w * 3].copy_from_slice(&data[y * stride..y * stride + w * 3]);
    }
    img
}

/// A monitor frame of one colour.
pub fn monitor_rgb(colour: Vec3) -> RgbImage {
    Playlist::still(Clip::Solid(colour)).frame(0.0)
}

pub fn monitor_buffer(colour: Vec3, pts: gst::ClockTime, duration: gst::ClockTime) -> gst::Buffer {
    let img = monitor_rgb(colour);
    buffer(
        &img,
        &rgb_caps(img.width as u32, img.height as u32, 30),
        pts,
        duration,
    )
}

/// Running time of the monitor frame that lit `buffer`, from its reference-timestamp meta.
pub fn monitor_time(buffer: &gst::BufferRef) -> Option<gst::ClockTime> {
    buffer
        .iter_meta::<gst::ReferenceTimestampMeta>()
        .find(|m| {
            m.reference()
                .can_intersect(&gstlsydrelight::lsydrelight::MONITOR_TIMESTAMP_CAPS)
        })
        .map(|m| m.timestamp())
}

pub fn stat(element: &gst::Element, field: &str) -> u64 {
    element
        .property::<gst::Structure>("stats")
        .get::<u64>(field)
        .unwrap()
}

/// Mean absolute difference of two images over a region.
pub fn mean_abs_diff(a: &RgbImage, b: &RgbImage) -> f64 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / a.data.len() as f64
}

pub fn element() -> gst::Element {
    init();
    gst::ElementFactory::make("lsydrelight")
        .build()
        .expect("lsydrelight element")
}

pub fn target(name: &str) -> String {
    checkout()
        .join(format!("models/targets/{name}.png"))
        .to_string_lossy()
        .into_owned()
}

pub const FRAME: gst::ClockTime = gst::ClockTime::from_nseconds(33_333_333);

pub fn frame_time(i: u64) -> gst::ClockTime {
    gst::ClockTime::from_nseconds(i * 1_000_000_000 / 30)
}
