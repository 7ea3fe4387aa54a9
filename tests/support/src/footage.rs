//! Footage through the element without a monitor stream, for the measures
//! that need no ground truth ([`crate::quality`]): decoding a clip or a still
//! to RGB frames, and relighting them in packed RGB or, as webcams deliver
//! them, in I420. The element's input and output come back in the format it
//! worked in ([`OwnedFrame`]s), for the measures to read as that format
//! carries them ([`crate::quality::View`]).

use std::path::Path;

use deskstage::monitor::RgbImage;
use gst::prelude::*;
use gstlsydrelight::frame::{Crop, DetailDenoiser, OwnedFrame, PixelFormat, YuvMatrix};
use gstlsydrelight::lsydrelight::frame_view;

use crate::quality::Region;
use crate::video::{FRAME, frame_time, rgb_caps, to_rgb};

/// Up to `frames` frames of a Y4M file (the simulator's recordings), as RGB.
pub fn read_y4m(path: &Path, frames: usize) -> Result<Vec<RgbImage>, String> {
    let mut reader =
        deskstage::io::Y4mReader::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut out = Vec::new();
    while out.len() < frames {
        match reader.next_frame() {
            Ok(Some(img)) => out.push(img),
            Ok(None) => break,
            Err(e) => return Err(format!("{}: {e}", path.display())),
        }
    }
    Ok(out)
}

/// scikit-image's astronaut portrait (public domain, fetched into `media` by
/// `scripts/setup.sh full`) scaled to 720 rows and centred in a 1280 x 720
/// frame of mid grey: a real face as a 720p webcam frames it.
pub fn portrait_720p(media: &Path) -> Result<RgbImage, String> {
    portrait_720p_leaning(media, 1.0)
}

/// [`portrait_720p`] with the person leaning towards the camera (`zoom` over 1)
/// or away from it: the portrait scaled by `zoom` about her face.
pub fn portrait_720p_leaning(media: &Path, zoom: f32) -> Result<RgbImage, String> {
    let path = media.join("astronaut.png");
    let portrait = image::open(&path)
        .map_err(|e| format!("{}: {e} (scripts/setup.sh full fetches it)", path.display()))?
        .to_rgb8();
    let (placed, corner) = (720.0, [280.0, 0.0]);
    let scale = placed / portrait.width() as f32;
    let face = [0, 1].map(|k| corner[k] + PORTRAIT_FACE.0[k] * scale);
    let side = (placed * zoom).round() as u32;
    let portrait =
        image::imageops::resize(&portrait, side, side, image::imageops::FilterType::Triangle);
    let corner = [0, 1].map(|k| (face[k] + zoom * (corner[k] - face[k])).round() as i64);
    let mut frame = image::RgbImage::from_pixel(1280, 720, image::Rgb([96, 96, 96]));
    image::imageops::overlay(&mut frame, &portrait, corner[0], corner[1]);
    Ok(RgbImage {
        width: 1280,
        height: 720,
        data: frame.into_raw(),
    })
}

/// The face in the 512 x 512 portrait as MediaPipe boxes it
/// (`models/face/check.json`): its centre and height, in pixels.
pub const PORTRAIT_FACE: ([f32; 2], f32) = ([224.5, 129.5], 95.0);

/// A face far from the camera: a 1080p frame of a grey wall with the portrait
/// shrunk so that its face is `face_fraction` of the frame's height, the face's
/// centre at `centre` (fractions of the frame's width and height). Returns the
/// frame and where the face is in it (centre and height, in pixels).
pub fn small_portrait_1080p(
    media: &Path,
    face_fraction: f32,
    centre: [f32; 2],
) -> Result<(RgbImage, [f32; 2], f32), String> {
    let path = media.join("astronaut.png");
    let portrait = image::open(&path)
        .map_err(|e| format!("{}: {e} (scripts/setup.sh full fetches it)", path.display()))?
        .to_rgb8();
    let (width, height) = (1920u32, 1080u32);
    let face_height = face_fraction * height as f32;
    let scale = face_height / PORTRAIT_FACE.1;
    let side = (portrait.width() as f32 * scale).round() as u32;
    let small =
        image::imageops::resize(&portrait, side, side, image::imageops::FilterType::Triangle);
    let face = [centre[0] * width as f32, centre[1] * height as f32];
    let corner = [0, 1].map(|k| (face[k] - PORTRAIT_FACE.0[k] * scale).round() as i64);
    let mut frame = image::RgbImage::from_pixel(width, height, image::Rgb([96, 96, 96]));
    image::imageops::overlay(&mut frame, &small, corner[0], corner[1]);
    let frame = RgbImage {
        width: width as usize,
        height: height as usize,
        data: frame.into_raw(),
    };
    Ok((frame, face, face_height))
}

/// Decodes up to `frames` frames of a video, or a still image repeated, as RGB.
pub fn decode(path: &Path, frames: usize) -> Result<Vec<RgbImage>, String> {
    let still = path.extension().is_some_and(|e| e == "png");
    let source = if still {
        format!("pngdec ! videoconvert ! imagefreeze num-buffers={frames}")
    } else {
        "decodebin ! videoconvert".to_string()
    };
    let pipeline = gst::parse::launch(&format!(
        "filesrc location=\"{}\" ! {source} ! video/x-raw,format=RGB \
         ! appsink name=sink sync=false",
        path.display()
    ))
    .map_err(|e| e.to_string())?
    .downcast::<gst::Bin>()
    .expect("a pipeline is a bin");
    let sink = pipeline
        .by_name("sink")
        .and_then(|s| s.downcast::<gst_app::AppSink>().ok())
        .expect("the appsink");
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| format!("cannot play {}: {e}", path.display()))?;
    let mut out = Vec::new();
    while out.len() < frames {
        let Ok(sample) = sink.pull_sample() else {
            break;
        };
        let (Some(buffer), Some(caps)) = (sample.buffer_owned(), sample.caps_owned()) else {
            break;
        };
        out.push(to_rgb(&buffer, &caps));
    }
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    if out.is_empty() {
        return Err(format!("no frames decoded from {}", path.display()));
    }
    Ok(out)
}

/// The pixel format frames reach the element in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Rgb,
    /// What most webcams and video files deliver: 4:2:0, chroma at half resolution.
    I420,
}

impl Format {
    pub fn parse(name: &str) -> Result<Format, String> {
        match name {
            "RGB" => Ok(Format::Rgb),
            "I420" => Ok(Format::I420),
            _ => Err("expected RGB or I420".into()),
        }
    }

    /// RGB frames converted into this format, then `element`.
    fn feeding(self, element: &str) -> String {
        match self {
            Format::Rgb => element.to_string(),
            // No dither: the conversion alone must not make noise the measures would count.
            Format::I420 => {
                format!("videoconvert dither=none ! video/x-raw,format=I420 ! {element}")
            }
        }
    }
}

/// `frames` converted into `format`: the input a camera in that format
/// gives, byte for byte what [`relight`] feeds the element, to compare its
/// output with.
pub fn through(frames: &[RgbImage], format: Format) -> Result<Vec<OwnedFrame>, String> {
    if format == Format::Rgb {
        return Ok(frames.iter().map(packed).collect());
    }
    Ok(run(frames, &format.feeding("identity"))?
        .into_iter()
        .map(|(frame, _)| frame)
        .collect())
}

/// An RGB image as a frame.
pub fn packed(img: &RgbImage) -> OwnedFrame {
    OwnedFrame {
        format: PixelFormat::Rgb,
        width: img.width,
        height: img.height,
        planes: vec![(img.data.clone(), 3 * img.width)],
        matrix: YuvMatrix::BT601_LIMITED,
    }
}

/// A packed RGB frame (from [`packed`], or made from one) as an RGB image:
/// its bytes, which are the image's, as its stride has no padding.
pub fn unpacked(frame: OwnedFrame) -> RgbImage {
    assert!(
        frame.format == PixelFormat::Rgb && frame.planes[0].1 == 3 * frame.width,
        "unpacked takes a packed RGB frame without padding, not {:?}",
        frame.format
    );
    let (width, height) = (frame.width, frame.height);
    let data = frame
        .planes
        .into_iter()
        .next()
        .expect("a packed frame has a plane")
        .0;
    RgbImage {
        width,
        height,
        data,
    }
}

/// A copy of a buffer of `caps` (packed RGB or I420) as a frame.
fn owned(buffer: &gst::Buffer, caps: &gst::CapsRef) -> Result<OwnedFrame, String> {
    let info = gst_video::VideoInfo::from_caps(caps).map_err(|e| e.to_string())?;
    let mapped = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer.as_ref(), &info)
        .map_err(|e| e.to_string())?;
    let frame = frame_view(&mapped).ok_or(format!("{caps}: not a format the element takes"))?;
    let planes = match frame.format {
        PixelFormat::Rgb => 1,
        PixelFormat::I420 => 3,
        other => return Err(format!("{other:?}: the measures read RGB and I420")),
    };
    Ok(OwnedFrame {
        format: frame.format,
        width: frame.width,
        height: frame.height,
        planes: frame.planes[..planes]
            .iter()
            .map(|p| (p.data.to_vec(), p.stride))
            .collect(),
        matrix: frame.matrix,
    })
}

/// What the element says it relit in a frame: its `face` region-of-interest
/// meta and the meta's `lsydrelight` parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Relit {
    /// The square relit.
    pub region: Region,
    /// The face in it, as the element placed it (its `face-*` parameters;
    /// where the meta came without them, [`Region::face_within`] the square).
    pub face: Region,
    /// How much of the change showed, in [0, 1] (less while a face fades in
    /// or out), and the width of its fade beyond the head and shoulders,
    /// in pixels. None where the meta came without its parameters:
    /// `videoconvert` copies the region but not them.
    pub shown: Option<(f32, usize)>,
}

impl Relit {
    /// Whether the element showed its change only in part (a face fading in or out).
    pub fn fading(&self) -> bool {
        self.shown.is_some_and(|(strength, _)| strength < 1.0)
    }
}

/// The frames relit by the element with no monitor stream by `model`, fed
/// in `format` and in that format, each with what the element relit in it
/// (None when it relit nothing).
///
/// `denoise` sets the element's property of that name. The measures of
/// [`crate::quality`] read the lighting change as the output over the input,
/// pixel by pixel, and denoising changes each pixel by the noise it removes,
/// which they read as blotches and steps of the change (on the film clip's
/// near-black pixels most): to measure the lighting change alone with it on,
/// compare the output with [`denoised`] input.
pub fn relight(
    frames: &[RgbImage],
    model: &Path,
    target: &Path,
    format: Format,
    denoise: bool,
) -> Result<Vec<(OwnedFrame, Option<Relit>)>, String> {
    relight_with(
        frames,
        model,
        &format!("denoise={denoise} target-location=\"{}\"", target.display()),
        format,
    )
}

/// [`relight`] with the element's other properties set by `properties`, as
/// gst-launch writes them (`target-preset=neon denoise=false`).
pub fn relight_with(
    frames: &[RgbImage],
    model: &Path,
    properties: &str,
    format: Format,
) -> Result<Vec<(OwnedFrame, Option<Relit>)>, String> {
    let element = format!(
        "lsydrelight name=r model-location=\"{}\" {properties}",
        model.display()
    );
    run(frames, &format.feeding(&element))
}

/// `frames` (the element's input, from [`through`]) as the element's
/// denoising leaves them before its lighting change: filtered by the
/// element's own code (`DetailDenoiser`) round the square, with the fade and
/// strength the element says it relit each frame with (`relit`, from
/// [`relight`]). A frame it relit nothing in passes, and the filtering starts
/// afresh after it, as the element's does.
pub fn denoised(frames: &[OwnedFrame], relit: &[Option<Relit>]) -> Result<Vec<OwnedFrame>, String> {
    let mut denoiser = DetailDenoiser::default();
    frames
        .iter()
        .zip(relit)
        .map(|(frame, relit)| {
            let mut frame = frame.clone();
            let Some(relit) = relit else {
                denoiser.reset();
                return Ok(frame);
            };
            let (strength, feather) = relit.shown.ok_or(
                "the element's face region came without its lsydrelight parameters \
                 (an element after it dropped them)",
            )?;
            let Region { x, y, size } = relit.region;
            denoiser.apply(
                &mut frame.frame_mut(),
                Crop { x, y, size },
                feather,
                strength,
            );
            Ok(frame)
        })
        .collect()
}

/// `frames` pushed through `middle` (a gst-launch fragment) one at a time,
/// as they come out of it, with what the element relit in each.
fn run(frames: &[RgbImage], middle: &str) -> Result<Vec<(OwnedFrame, Option<Relit>)>, String> {
    let (w, h) = (frames[0].width as u32, frames[0].height as u32);
    let caps = rgb_caps(w, h, 30);
    let pipeline = gst::parse::launch(&format!(
        "appsrc name=src format=time ! {middle} ! appsink name=sink sync=false"
    ))
    .map_err(|e| e.to_string())?
    .downcast::<gst::Bin>()
    .expect("a pipeline is a bin");
    let src = pipeline
        .by_name("src")
        .and_then(|s| s.downcast::<gst_app::AppSrc>().ok())
        .expect("the appsrc");
    let sink = pipeline
        .by_name("sink")
        .and_then(|s| s.downcast::<gst_app::AppSink>().ok())
        .expect("the appsink");
    src.set_caps(Some(&caps));
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| format!("{middle} does not start: {e}"))?;
    let mut out = Vec::with_capacity(frames.len());
    for (i, img) in frames.iter().enumerate() {
        let mut buffer = gst::Buffer::from_mut_slice(img.data.clone());
        {
            let b = buffer.get_mut().expect("a new buffer is writable");
            b.set_pts(frame_time(i as u64));
            b.set_duration(FRAME);
        }
        src.push_buffer(buffer).map_err(|e| e.to_string())?;
        let sample = sink.pull_sample().map_err(|_| "the element stopped")?;
        let buffer = sample.buffer_owned().expect("a buffer");
        let frame = owned(&buffer, sample.caps().expect("caps"))?;
        let relit = match buffer.meta::<gst_video::VideoRegionOfInterestMeta>() {
            None => None,
            Some(roi) => {
                let (x, y, size, _) = roi.rect();
                let field = |e: gst::structure::GetError<_>| format!("the face region's {e}");
                let region = Region {
                    x: x as usize,
                    y: y as usize,
                    size: size as usize,
                };
                let (shown, face) = match roi.param("lsydrelight") {
                    None => (None, region.face_within()),
                    Some(p) => {
                        let corner = |name| p.get::<i32>(name).map(|c| c.max(0) as usize);
                        (
                            Some((
                                p.get::<f64>("strength").map_err(field)? as f32,
                                p.get::<u32>("feather").map_err(field)? as usize,
                            )),
                            Region {
                                x: corner("face-x").map_err(field)?,
                                y: corner("face-y").map_err(field)?,
                                size: p.get::<u32>("face-size").map_err(field)? as usize,
                            },
                        )
                    }
                };
                Some(Relit {
                    region,
                    face,
                    shown,
                })
            }
        };
        out.push((frame, relit));
    }
    let _ = src.end_of_stream();
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    Ok(out)
}
