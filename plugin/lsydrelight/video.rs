//! The bridge between GStreamer's video and the GStreamer-free frame code: the
//! caps the pads take, error advice about them, views of mapped `gst_video`
//! frames as [`Frame`]/[`FrameMut`], and buffer timing.

use gst_base::prelude::*;
use gst_video::VideoFormat;
use gst_video::prelude::*;

use crate::frame::{Frame, FrameMut, PixelFormat, Plane, YuvMatrix};

/// Every format both video pads take.
pub const FORMATS: [VideoFormat; 9] = [
    VideoFormat::I420,
    VideoFormat::Nv12,
    VideoFormat::Y444,
    VideoFormat::Rgba,
    VideoFormat::Bgra,
    VideoFormat::Rgbx,
    VideoFormat::Bgrx,
    VideoFormat::Rgb,
    VideoFormat::Bgr,
];

/// Smallest face frame: the crop and the lighting transfer need a few pixels to work with.
pub const MIN_FACE_SIZE: u32 = 16;

/// The face pad's template: the formats above, any size. Frames smaller than
/// [`MIN_FACE_SIZE`] are refused when their caps arrive, with an error that says
/// so: refusing them in the template would leave an upstream `videoconvert`
/// unable to negotiate, and the pipeline hanging in preroll with no message.
pub fn face_caps() -> gst::Caps {
    any_size_caps()
}

/// Monitor content: the same formats, any size.
pub fn monitor_caps() -> gst::Caps {
    any_size_caps()
}

fn any_size_caps() -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format_list(FORMATS)
        .build()
}

/// Why the face pad cannot take video of this size, if it cannot.
pub fn face_size_problem(info: &gst_video::VideoInfo) -> Option<String> {
    (info.width() < MIN_FACE_SIZE || info.height() < MIN_FACE_SIZE).then(|| {
        format!(
            "face video of {}x{} is too small: frames must be at least {MIN_FACE_SIZE}x{MIN_FACE_SIZE}",
            info.width(),
            info.height()
        )
    })
}

/// What a pad takes and how to give it that, for error messages.
pub fn caps_advice(pad: &str) -> String {
    let formats: Vec<&str> = FORMATS.iter().map(|f| f.to_str().as_str()).collect();
    let size = if pad == "sink" {
        format!(" of at least {MIN_FACE_SIZE}x{MIN_FACE_SIZE}")
    } else {
        String::new()
    };
    format!(
        "{pad} takes raw video in {}{size}; put videoconvert (and videoscale) in front of it",
        formats.join(", ")
    )
}

fn pixel_format(f: VideoFormat) -> Option<PixelFormat> {
    Some(match f {
        VideoFormat::I420 => PixelFormat::I420,
        VideoFormat::Nv12 => PixelFormat::Nv12,
        VideoFormat::Y444 => PixelFormat::Y444,
        VideoFormat::Rgba => PixelFormat::Rgba,
        VideoFormat::Bgra => PixelFormat::Bgra,
        VideoFormat::Rgbx => PixelFormat::Rgbx,
        VideoFormat::Bgrx => PixelFormat::Bgrx,
        VideoFormat::Rgb => PixelFormat::Rgb,
        VideoFormat::Bgr => PixelFormat::Bgr,
        _ => return None,
    })
}

fn yuv_matrix(info: &gst_video::VideoInfo) -> YuvMatrix {
    let c = info.colorimetry();
    let (kr, kb) = match c.matrix() {
        gst_video::VideoColorMatrix::Bt709 => (0.2126, 0.0722),
        gst_video::VideoColorMatrix::Bt2020 => (0.2627, 0.0593),
        gst_video::VideoColorMatrix::Smpte240m => (0.212, 0.087),
        gst_video::VideoColorMatrix::Fcc => (0.30, 0.11),
        _ => (0.299, 0.114),
    };
    YuvMatrix {
        kr,
        kb,
        limited: c.range() != gst_video::VideoColorRange::Range0_255,
    }
}

/// A readable frame as the frame code sees it; None for a format it cannot read.
pub fn frame_view<'a>(f: &'a gst_video::VideoFrameRef<&gst::BufferRef>) -> Option<Frame<'a>> {
    let format = pixel_format(f.format())?;
    let strides = f.plane_stride();
    let plane = |i: usize| -> Plane<'a> {
        let i = i.min(f.n_planes() as usize - 1);
        Plane {
            data: f.plane_data(i as u32).unwrap_or(&[]),
            stride: strides[i] as usize,
        }
    };
    Some(Frame {
        format,
        width: f.width() as usize,
        height: f.height() as usize,
        planes: [plane(0), plane(1), plane(2)],
        matrix: yuv_matrix(f.info()),
    })
}

/// Runs `body` on a writable frame as the frame code sees it; None for a format
/// it cannot write.
pub fn with_frame_mut<R>(
    f: &mut gst_video::VideoFrameRef<&mut gst::BufferRef>,
    body: impl FnOnce(&mut FrameMut) -> R,
) -> Option<R> {
    let format = pixel_format(f.format())?;
    let (width, height) = (f.width() as usize, f.height() as usize);
    let matrix = yuv_matrix(f.info());
    let strides: Vec<usize> = f.plane_stride().iter().map(|&s| s as usize).collect();
    let n = f.n_planes() as usize;
    let mut planes = f.planes_data_mut().into_iter().take(n);
    let mut next = |i: usize| -> (&mut [u8], usize) {
        match planes.next() {
            Some(p) => (p, strides[i]),
            None => (&mut [], 0),
        }
    };
    let p0 = next(0);
    let p1 = next(1);
    let p2 = next(2);
    let mut fm = FrameMut {
        format,
        width,
        height,
        planes: [p0, p1, p2],
        matrix,
    };
    Some(body(&mut fm))
}

/// A buffer the aggregator made from a GAP event: no picture, only time.
pub fn is_gap(buffer: &gst::BufferRef) -> bool {
    buffer.flags().contains(gst::BufferFlags::GAP) && buffer.size() == 0
}

/// A buffer's running time in its pad's segment.
pub fn running_time(
    pad: &gst_base::AggregatorPad,
    pts: Option<gst::ClockTime>,
) -> Option<gst::ClockTime> {
    pad.segment()
        .downcast_ref::<gst::ClockTime>()?
        .to_running_time(pts?)
}

/// One frame's duration at the caps' frame rate, if it has one.
pub fn frame_duration(info: &gst_video::VideoInfo) -> Option<gst::ClockTime> {
    let fps = info.fps();
    (fps.numer() > 0).then(|| {
        gst::ClockTime::SECOND
            .mul_div_floor(fps.denom() as u64, fps.numer() as u64)
            .unwrap_or(gst::ClockTime::ZERO)
    })
}
