//! Relighting one recording: outputs under temporary names, the pipeline run
//! to its end (or to a clean stop on Ctrl-C) with a progress bar, and the
//! outputs renamed into place only then.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use gst::prelude::*;

use super::diagnose;
use super::graph::{self, Container};
use crate::exit::{Failure, Status};
use crate::interrupt;
use crate::partial::Partial;
use crate::progress::{Bar, Bars};

/// What every recording of a run is relit with.
pub struct Settings {
    pub model: Option<PathBuf>,
    pub target: Option<super::target::Target>,
    pub monitor_offset_ns: i64,
    pub quality: u32,
}

/// An output file and the container its extension names.
pub struct Output {
    pub path: PathBuf,
    pub container: Container,
}

impl Output {
    pub fn new(path: PathBuf) -> Option<Output> {
        Container::of(&path).map(|container| Output { path, container })
    }
}

/// The files of one recording.
pub struct Files {
    pub face: PathBuf,
    pub screen: Option<PathBuf>,
    /// `--target` when it names a file, for messages about a video target.
    pub target_video: Option<PathBuf>,
    pub out: Output,
    pub predicted: Option<Output>,
}

pub enum Outcome {
    /// Relit to the end.
    Done {
        frames: u64,
        time: Duration,
    },
    /// Stopped by Ctrl-C; the frames relit so far were kept.
    Stopped {
        frames: u64,
        time: Duration,
    },
    /// Ctrl-C came before a frame was relit; nothing was written.
    NotStarted,
    Failed(Failure),
}

impl Outcome {
    /// How the recording went, in a line: the result (padded to `column`), the
    /// time and the speed, and the files written.
    pub fn line(&self, name: &str, files: Option<&Files>, column: usize) -> String {
        let rate = |frames: &u64, time: &Duration| {
            format!(
                "{frames} frames in {:.1} s, {:.1} fps",
                time.as_secs_f64(),
                *frames as f64 / time.as_secs_f64().max(1e-9)
            )
        };
        let written = files.map_or(String::new(), |f| {
            let mut s = f.out.path.display().to_string();
            if let Some(p) = &f.predicted {
                s += &format!(" and {}", p.path.display());
            }
            s
        });
        let (status, text) = match self {
            Outcome::Done { frames, time } => {
                ("ok", format!("{} -> {written}", rate(frames, time)))
            }
            Outcome::Stopped { frames, time } => (
                "stopped",
                format!("{} -> {written} (all before Ctrl-C)", rate(frames, time)),
            ),
            Outcome::NotStarted => ("not started", "Ctrl-C came first; nothing written".into()),
            Outcome::Failed(f) => ("failed", f.to_string()),
        };
        format!("{status:<column$} {name}: {text}")
    }
}

/// The run's exit status: interrupted when Ctrl-C stopped anything, else
/// failed when anything failed.
pub fn status(outcomes: &[Outcome]) -> Status {
    let any = |f: fn(&Outcome) -> bool| outcomes.iter().any(f);
    if any(|o| matches!(o, Outcome::Stopped { .. } | Outcome::NotStarted)) {
        Status::Interrupted
    } else if any(|o| matches!(o, Outcome::Failed(_))) {
        Status::Failure
    } else {
        Status::Success
    }
}

pub fn run(settings: &Settings, files: &Files, bars: &Bars, bar: &Bar) -> Outcome {
    if interrupt::stop_requested() {
        return Outcome::NotStarted;
    }
    let out = Partial::new(&files.out.path);
    let predicted = files.predicted.as_ref().map(|p| Partial::new(&p.path));
    let graph = match graph::build(
        settings,
        files,
        out.temp(),
        predicted.as_ref().map(|p| p.temp()),
    ) {
        Ok(g) => g,
        Err(f) => return Outcome::Failed(f),
    };
    let started = Instant::now();
    let end = watch(&graph, files, bars, bar);
    let time = started.elapsed();
    let frames = graph.frames();
    let predicted_frames = graph.predicted_frames();
    // Stops the pipeline, which closes the files before they are renamed.
    drop(graph);
    bar.finish();
    let kept = match end {
        Err(f) => return Outcome::Failed(f),
        Ok(End::BeforeFirstFrame) => return Outcome::NotStarted,
        Ok(End::Complete) if frames == 0 => {
            return Outcome::Failed(Failure::new(format!(
                "--face {}: its video stream has no frames",
                files.face.display()
            )));
        }
        Ok(end) => end,
    };
    // With no face ever found nothing was predicted: a file without frames
    // would not play, so none is written.
    let predicted = match predicted {
        Some(p) if predicted_frames == 0 => {
            bars.note(&format!(
                "warning: {}: no face was found in any frame, so there is no predicted monitor; \
                 {} was not written",
                files.face.display(),
                p.dest().display()
            ));
            // Dropped uncommitted: its temporary file is removed.
            None
        }
        kept => kept,
    };
    let committed = out
        .commit()
        .and_then(|_| predicted.map_or(Ok(()), Partial::commit));
    match (committed, kept) {
        (Err(f), _) => Outcome::Failed(f),
        (Ok(()), End::Stopped) => Outcome::Stopped { frames, time },
        (Ok(()), _) => Outcome::Done { frames, time },
    }
}

/// How a pipeline that did not fail ended.
enum End {
    /// At the end of the face recording.
    Complete,
    /// Ctrl-C, after relit frames: they were drained into finished files.
    Stopped,
    /// Ctrl-C before any frame was relit: there is nothing to keep.
    BeforeFirstFrame,
}

/// Plays the pipeline to its end, or to a clean stop on Ctrl-C.
fn watch(graph: &graph::Graph, files: &Files, bars: &Bars, bar: &Bar) -> Result<End, Failure> {
    let pipeline = &graph.pipeline;
    let bus = pipeline
        .bus()
        .ok_or_else(|| Failure::new("internal error: a pipeline without a bus"))?;
    let name = files.face.file_name().unwrap_or_default().to_string_lossy();
    let mut missing_plugins = Vec::new();
    let mut stopping = false;
    if pipeline.set_state(gst::State::Playing).is_err() {
        // The element that refused to start has posted why.
        let error =
            bus.timed_pop_filtered(gst::ClockTime::from_seconds(5), &[gst::MessageType::Error]);
        return Err(match error.as_ref().map(|m| m.view()) {
            Some(gst::MessageView::Error(e)) => diagnose::error(e, files, &missing_plugins),
            _ => Failure::new(format!("{name}: the pipeline would not start")),
        });
    }
    loop {
        if !stopping && interrupt::stop_requested() {
            if graph.frames() == 0 {
                return Ok(End::BeforeFirstFrame);
            }
            // End-of-stream from the sources, as `gst-launch-1.0 -e` sends: every
            // branch drains and the muxers write their indexes, so the file plays.
            pipeline.send_event(gst::event::Eos::new());
            stopping = true;
        }
        bar.update(graph.frames(), || graph.expected_frames());
        let Some(message) = bus.timed_pop(gst::ClockTime::from_mseconds(100)) else {
            continue;
        };
        if graph::face_without_video(&message) {
            return Err(Failure::new(format!(
                "--face {}: no video stream; pass the recording that holds the video of the face",
                files.face.display()
            )));
        }
        match message.view() {
            gst::MessageView::Eos(_) if stopping => return Ok(End::Stopped),
            gst::MessageView::Eos(_) => return Ok(End::Complete),
            gst::MessageView::Error(e) => {
                return Err(diagnose::error(e, files, &missing_plugins));
            }
            gst::MessageView::Warning(w) => {
                bars.note(&format!("warning: {name}: {}", diagnose::warning(w)));
            }
            gst::MessageView::Element(_) => {
                if let Ok(m) = gst_pbutils::MissingPluginMessage::parse(&message) {
                    missing_plugins.push(m.description().to_string());
                }
            }
            _ => {}
        }
    }
}
