//! Frames in and out of the element: caps, RGB images as buffers of any format
//! the element takes (converted by GStreamer's own converter) and back, and
//! frame times.

use deskstage::math::Vec3;
use deskstage::monitor::RgbImage;
use gst_video::prelude::*;

use crate::person::monitor_rgb;

/// Every format the element's `sink` takes.
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

/// One frame's duration at 30 fps.
pub const FRAME: gst::ClockTime = gst::ClockTime::from_nseconds(33_333_333);

/// The time of frame `i` at 30 fps.
pub fn frame_time(i: u64) -> gst::ClockTime {
    gst::ClockTime::from_nseconds(i * 1_000_000_000 / 30)
}

/// Raw video caps of a format, size and rate.
pub fn caps(format: gst_video::VideoFormat, w: u32, h: u32, fps: i32) -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format(format)
        .width(w as i32)
        .height(h as i32)
        .framerate(gst::Fraction::new(fps, 1))
        .build()
}

/// Packed RGB caps of a size and rate.
pub fn rgb_caps(w: u32, h: u32, fps: i32) -> gst::Caps {
    caps(gst_video::VideoFormat::Rgb, w, h, fps)
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

/// A 30 fps monitor frame of one colour, as an RGB buffer stamped at `pts`.
pub fn monitor_buffer(colour: Vec3, pts: gst::ClockTime, duration: gst::ClockTime) -> gst::Buffer {
    let img = monitor_rgb(colour);
    buffer(
        &img,
        &rgb_caps(img.width as u32, img.height as u32, 30),
        pts,
        duration,
    )
}

/// Mean absolute difference of two images of the same size, on 0-255.
pub fn mean_abs_diff(a: &RgbImage, b: &RgbImage) -> f64 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / a.data.len() as f64
}
