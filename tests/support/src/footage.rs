//! Footage through the element without a monitor stream, for the measures
//! that need no ground truth ([`crate::quality`]): decoding a clip or a still
//! to RGB frames, and relighting them.

use std::path::Path;

use deskstage::monitor::RgbImage;
use gst::prelude::*;

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

/// The frames relit by the element with no monitor stream by `model`, each
/// with the square the element relit (its `face` region-of-interest meta; None
/// when it relit none).
pub fn relight(
    frames: &[RgbImage],
    model: &Path,
    target: &Path,
) -> Result<Vec<(RgbImage, Option<Region>)>, String> {
    let (w, h) = (frames[0].width as u32, frames[0].height as u32);
    let caps = rgb_caps(w, h, 30);
    let pipeline = gst::parse::launch(&format!(
        "appsrc name=src format=time ! lsydrelight name=r model-location=\"{}\" \
         target-location=\"{}\" ! appsink name=sink sync=false",
        model.display(),
        target.display()
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
        .map_err(|e| format!("the element does not start: {e}"))?;
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
        let region = buffer
            .meta::<gst_video::VideoRegionOfInterestMeta>()
            .map(|roi| {
                let (x, y, size, _) = roi.rect();
                Region {
                    x: x as usize,
                    y: y as usize,
                    size: size as usize,
                }
            });
        out.push((to_rgb(&buffer, &caps), region));
    }
    let _ = src.end_of_stream();
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    Ok(out)
}
