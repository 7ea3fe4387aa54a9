//! Relights a recorded call: a face video and the screen recording of what the
//! person's monitor showed. Writes the relit video, the predicted-monitor video
//! and a side-by-side image, and says where they are.
//!
//! ```text
//! cargo run --release --example relight_recording -- \
//!     [--face examples/data/call/face.mp4] [--monitor examples/data/call/monitor.mp4] \
//!     [--target models/targets/sunset.png] [--model models/default] [--out results/demo] [--frame 150]
//! ```

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use gst::prelude::*;
use gst_video::prelude::*;
use lsydrelight_testkit::{checkout, default_model, init};

struct Args {
    face: PathBuf,
    monitor: PathBuf,
    target: PathBuf,
    model: PathBuf,
    out: PathBuf,
    frame: usize,
}

fn parse() -> Result<Args, String> {
    let root = checkout();
    let mut a = Args {
        face: root.join("examples/data/call/face.mp4"),
        monitor: root.join("examples/data/call/monitor.mp4"),
        target: root.join("models/targets/sunset.png"),
        model: default_model(),
        out: root.join("results/demo"),
        frame: 150,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let v = it.next().ok_or(format!("{k} needs a value"))?;
        match k.as_str() {
            "--face" => a.face = v.into(),
            "--monitor" => a.monitor = v.into(),
            "--target" => a.target = v.into(),
            "--model" => a.model = v.into(),
            "--out" => a.out = v.into(),
            "--frame" => a.frame = v.parse().map_err(|_| "--frame takes a number")?,
            _ => return Err(format!("unknown argument {k}")),
        }
    }
    for (what, p) in [
        ("face video", &a.face),
        ("monitor video", &a.monitor),
        ("target image", &a.target),
    ] {
        if !p.exists() {
            return Err(format!("the {what} {} does not exist", p.display()));
        }
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

fn main() -> Result<(), String> {
    let a = parse()?;
    init();
    std::fs::create_dir_all(&a.out).map_err(|e| format!("{}: {e}", a.out.display()))?;
    let relit = a.out.join("relit.mp4");
    let predicted = a.out.join("predicted-monitor.mp4");
    let rgb = "videoconvert ! video/x-raw,format=RGB ! appsink sync=false";
    // tune=zerolatency: x264's default lookahead holds more frames than a tee branch's
    // queue does while the appsinks preroll, which stalls the whole pipeline.
    let desc = format!(
        "lsydrelight name=r \
         filesrc location=\"{face}\" ! decodebin ! videoconvert ! tee name=face \
           face. ! queue ! r.sink \
           face. ! queue ! {rgb} name=original \
         filesrc location=\"{monitor}\" ! decodebin ! videoconvert ! tee name=screen \
           screen. ! queue ! r.monitor_sink \
           screen. ! queue ! {rgb} name=shown \
         r.src ! tee name=out \
           out. ! queue ! videoconvert ! x264enc speed-preset=fast tune=zerolatency ! mp4mux ! filesink location=\"{relit}\" \
           out. ! queue ! {rgb} name=relit \
         r.monitor_src ! tee name=pred \
           pred. ! queue ! videoconvert ! x264enc speed-preset=fast tune=zerolatency ! mp4mux ! filesink location=\"{predicted}\" \
           pred. ! queue ! {rgb} name=predicted",
        face = a.face.display(),
        monitor = a.monitor.display(),
        relit = relit.display(),
        predicted = predicted.display(),
    );
    let pipeline = gst::parse::launch(&desc)
        .map_err(|e| format!("cannot build the pipeline: {e}"))?
        .downcast::<gst::Pipeline>()
        .map_err(|_| "not a pipeline")?;
    let r = pipeline.by_name("r").ok_or("no lsydrelight")?;
    r.set_property(
        "target-location",
        a.target.to_str().ok_or("target path is not UTF-8")?,
    );
    r.set_property(
        "model-location",
        a.model.to_str().ok_or("model path is not UTF-8")?,
    );
    let grab = |name: &str| -> Result<Grab, String> {
        let sink = pipeline.by_name(name).ok_or(format!("no {name}"))?;
        Ok(grabber(
            &sink
                .downcast::<gst_app::AppSink>()
                .map_err(|_| "not an appsink")?,
            a.frame,
        ))
    };
    let (original, shown, relit_grab, predicted_grab) = (
        grab("original")?,
        grab("shown")?,
        grab("relit")?,
        grab("predicted")?,
    );

    let started = std::time::Instant::now();
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| format!("cannot play: {e}"))?;
    let bus = pipeline.bus().ok_or("no bus")?;
    let result = loop {
        let Some(msg) = bus.timed_pop(gst::ClockTime::from_seconds(600)) else {
            break Err("no progress for 10 minutes".to_string());
        };
        match msg.view() {
            gst::MessageView::Eos(_) => break Ok(()),
            gst::MessageView::Error(e) => {
                break Err(format!("{} ({})", e.error(), e.debug().unwrap_or_default()));
            }
            gst::MessageView::Warning(w) => eprintln!("warning: {}", w.error()),
            _ => {}
        }
    };
    let stats = r.property::<gst::Structure>("stats");
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    result?;
    let frames = stats.get::<u64>("frames").unwrap_or(0);
    println!(
        "relit {frames} frames in {:.1} s ({} with the monitor's light, {} with the predicted light)",
        started.elapsed().as_secs_f64(),
        stats.get::<u64>("known-source").unwrap_or(0),
        stats.get::<u64>("predicted-source").unwrap_or(0)
    );

    let panels: Vec<(usize, usize, Vec<u8>)> = [&shown, &original, &relit_grab, &predicted_grab]
        .iter()
        .map(|g| g.lock().unwrap().clone())
        .collect::<Option<_>>()
        .ok_or(format!(
            "the recording has fewer than {} frames",
            a.frame + 1
        ))?;
    let sheet = a.out.join("side-by-side.png");
    let height = panels[1].1;
    write_png(&sheet, &side_by_side(&panels, height))?;
    println!("relit video:        {}", relit.display());
    println!("predicted monitor:  {}", predicted.display());
    println!(
        "side by side:       {} (frame {}: what the monitor showed, the face as filmed, relit to {}, the predicted monitor)",
        sheet.display(),
        a.frame,
        a.target.file_stem().unwrap_or_default().to_string_lossy()
    );
    Ok(())
}
