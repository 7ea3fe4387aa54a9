//! Puts one frame of several videos side by side in a PNG: `scripts/demo.sh` shows
//! frame 150 of what the monitor showed, the face as filmed, the face relit and the
//! predicted monitor, the last two read back from what `lsydrelight relight` wrote.
//!
//! ```text
//! cargo run --release --example side_by_side -- [--frame 150] --out sheet.png VIDEO...
//! ```

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use clap::Parser;
use gst::prelude::*;
use gst_video::prelude::*;
use lsydrelight_testkit::init;

/// One frame of several videos side by side in a PNG.
#[derive(Parser)]
struct Args {
    /// The videos, left to right.
    #[arg(required = true)]
    videos: Vec<PathBuf>,
    /// The PNG to write.
    #[arg(long)]
    out: PathBuf,
    /// The frame taken from each video.
    #[arg(long, default_value_t = 150)]
    frame: usize,
}

fn checked_args() -> Result<Args, String> {
    let a = Args::parse();
    if let Some(missing) = a.videos.iter().find(|p| !p.exists()) {
        return Err(format!("{} does not exist", missing.display()));
    }
    Ok(a)
}

/// An RGB frame grabbed from a branch of the pipeline.
type Grab = Arc<Mutex<Option<(usize, usize, Vec<u8>)>>>;

/// An appsink that keeps the `index`-th frame it sees.
fn grabber(sink: &gst_app::AppSink, index: usize) -> Grab {
    let grab: Grab = Arc::new(Mutex::new(None));
    let (g, mut seen) = (grab.clone(), 0usize);
    sink.set_callbacks(
        gst_app::AppSinkCallbacks::builder()
            .new_sample(move |s| {
                let sample = s.pull_sample().map_err(|_| gst::FlowError::Eos)?;
                if seen == index
                    && let (Some(buffer), Some(caps)) = (sample.buffer(), sample.caps())
                    && let Ok(info) = gst_video::VideoInfo::from_caps(caps)
                    && let Ok(frame) =
                        gst_video::VideoFrameRef::from_buffer_ref_readable(buffer, &info)
                {
                    let (w, h) = (info.width() as usize, info.height() as usize);
                    let stride = frame.plane_stride()[0] as usize;
                    let data = frame.plane_data(0).unwrap_or(&[]);
                    let rgb = (0..h)
                        .flat_map(|y| data[y * stride..y * stride + w * 3].iter().copied())
                        .collect();
                    *g.lock().unwrap() = Some((w, h, rgb));
                }
                seen += 1;
                Ok(gst::FlowSuccess::Ok)
            })
            .build(),
    );
    grab
}

/// Panels side by side, each scaled to `height` rows (nearest neighbour), with a gap.
fn side_by_side(panels: &[(usize, usize, Vec<u8>)], height: usize) -> (usize, usize, Vec<u8>) {
    let gap = 8;
    let widths: Vec<usize> = panels.iter().map(|(w, h, _)| w * height / h).collect();
    let total = widths.iter().sum::<usize>() + gap * (panels.len() - 1);
    let mut out = vec![255u8; total * height * 3];
    let mut x0 = 0;
    for ((w, h, data), &pw) in panels.iter().zip(&widths) {
        for y in 0..height {
            for x in 0..pw {
                let (sx, sy) = (x * w / pw, y * h / height);
                let s = (sy * w + sx) * 3;
                let d = (y * total + x0 + x) * 3;
                out[d..d + 3].copy_from_slice(&data[s..s + 3]);
            }
        }
        x0 += pw + gap;
    }
    (total, height, out)
}

fn write_png(path: &Path, (w, h, data): &(usize, usize, Vec<u8>)) -> Result<(), String> {
    let file = std::fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), *w as u32, *h as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()
        .and_then(|mut wr| wr.write_image_data(data))
        .map_err(|e| e.to_string())
}

/// The `index`-th frame of a video, as RGB.
fn frame_of(video: &Path, index: usize) -> Result<(usize, usize, Vec<u8>), String> {
    let pipeline = gst::parse::launch(&format!(
        "filesrc location=\"{}\" ! decodebin ! videoconvert ! video/x-raw,format=RGB ! appsink name=grab sync=false",
        video.display()
    ))
    .map_err(|e| format!("cannot build the pipeline: {e}"))?
    .downcast::<gst::Pipeline>()
    .map_err(|_| "not a pipeline")?;
    let sink = pipeline
        .by_name("grab")
        .and_then(|s| s.downcast::<gst_app::AppSink>().ok())
        .ok_or("no appsink")?;
    let grab = grabber(&sink, index);
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| format!("cannot play {}: {e}", video.display()))?;
    let bus = pipeline.bus().ok_or("no bus")?;
    let result = loop {
        let Some(msg) = bus.timed_pop(gst::ClockTime::from_seconds(60)) else {
            break Err(format!("{}: no progress for a minute", video.display()));
        };
        match msg.view() {
            gst::MessageView::Eos(_) => break Ok(()),
            gst::MessageView::Error(e) => break Err(format!("{}: {}", video.display(), e.error())),
            _ => {}
        }
    };
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    result?;
    let frame = grab.lock().unwrap().take();
    frame.ok_or(format!(
        "{} has fewer than {} frames",
        video.display(),
        index + 1
    ))
}

fn main() -> Result<(), String> {
    let a = checked_args()?;
    init();
    let panels = a
        .videos
        .iter()
        .map(|v| frame_of(v, a.frame))
        .collect::<Result<Vec<_>, _>>()?;
    let height = panels.iter().map(|p| p.1).max().unwrap_or(0);
    write_png(&a.out, &side_by_side(&panels, height))?;
    println!("side by side: {} (frame {})", a.out.display(), a.frame);
    Ok(())
}
