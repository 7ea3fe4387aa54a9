//! `--first-frame`: the time from PLAYING to the first relit buffer of a
//! fresh live 720p pipeline.

use std::sync::Mutex;
use std::time::Instant;

use gst::prelude::*;
use lsydrelight_testkit::init;

/// Milliseconds from PLAYING to the first relit buffer of a fresh live pipeline,
/// `repeats` times in this process.
pub(crate) fn first_frame(repeats: usize) -> Result<Vec<f64>, String> {
    init();
    let mut times = Vec::new();
    for _ in 0..repeats {
        let pipeline = gst::parse::launch(
            "videotestsrc is-live=true ! video/x-raw,width=1280,height=720,framerate=30/1 \
             ! lsydrelight name=r ! fakesink sync=false",
        )
        .map_err(|e| e.to_string())?
        .downcast::<gst::Bin>()
        .expect("a pipeline is a bin");
        let (tx, rx) = std::sync::mpsc::channel();
        let tx = Mutex::new(Some(tx));
        let relit = pipeline.by_name("r").expect("the element");
        relit
            .static_pad("src")
            .expect("src")
            .add_probe(gst::PadProbeType::BUFFER, move |_, _| {
                if let Some(tx) = tx.lock().unwrap().take() {
                    let _ = tx.send(Instant::now());
                }
                gst::PadProbeReturn::Ok
            });
        let started = Instant::now();
        pipeline
            .set_state(gst::State::Playing)
            .map_err(|e| e.to_string())?;
        let first = rx
            .recv_timeout(std::time::Duration::from_secs(30))
            .map_err(|_| "no relit frame within 30 s")?;
        times.push(first.duration_since(started).as_secs_f64() * 1e3);
        pipeline
            .set_state(gst::State::Null)
            .map_err(|e| e.to_string())?;
    }
    Ok(times)
}
