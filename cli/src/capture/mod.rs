//! `lsydrelight capture`: records one session of a personal light stage, the
//! webcam and the screen in one pipeline on one clock, into the capture folder
//! that `lsydrelight train` reads (`CAPTURE-LAYOUT.md`), and tells the user
//! while recording whether the session is any good.

mod folder;
mod graph;
pub mod guidance;
mod record;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use gst::prelude::*;

use crate::exit::{Failure, Status};
use crate::interrupt;
use crate::partial::Partial;
use crate::progress::{Bars, StatusLine};
use folder::Capture;
use graph::{Fragments, Part, Playlist};
use record::Recorder;

/// Record a session of your own light stage: your webcam while your monitor shows varied content
#[derive(clap::Args)]
#[command(
    override_usage = "lsydrelight capture --out DIR [--camera FRAGMENT] [--screen FRAGMENT | --playlist FILE...] \
        [--seconds N] [--held-out] [--keep-screen]",
    long_about = "Record a session of your own light stage: your webcam while your monitor shows \
        varied content.\n\n\
        Sit at your desk facing the webcam, with the room as dark as you can make it, and watch \
        varied videos full-screen (or pass --playlist to have them played); hold your head still \
        for 2 to 3 s at a time while the screen changes, then turn or tilt it to a new pose, \
        talk and smile now and then. The webcam and the screen are recorded together, in one \
        GStreamer pipeline on one clock, into --out DIR as a new session (session-000, \
        session-001, ...; capture.json lists them). `lsydrelight train` makes a model of you \
        from the folder.\n\n\
        While recording, a status line counts the usable frames (a face found, large enough, \
        the screen's light known) and how many of them pair with another (the same pose under \
        different screen light: what the model learns from), the monitor's share of the light on your face (measured from \
        how your face's brightness follows the screen's), and the head poses covered; warnings \
        say when the room light overpowers the monitor, when your face leaves the picture, \
        when your pose and expression stop changing and when no pose has repeated for a while. Their summary is kept in the session's \
        session.json.\n\n\
        Privacy: by default no screen content is stored, only the monitor's light: each screen \
        frame averaged down to a 16 x 32 grid of colours (light.npy), in which text, faces and \
        pictures cannot be made out. --keep-screen also stores the screen itself as \
        screen.mkv: everything your screen showed while recording, messages, documents and \
        passwords in view included. Keep it only when you need it (to check the light), and \
        never share such a folder.\n\n\
        Ctrl-C ends the session cleanly: what was recorded so far is finished and kept. A \
        second Ctrl-C aborts and keeps nothing.",
    after_help = concat!(
        "Examples:
  lsydrelight capture --out me --seconds 600
  lsydrelight capture --out me --playlist clips/*.mp4
  lsydrelight capture --out me --held-out --seconds 120
  lsydrelight capture --out me --camera \"v4l2src device=/dev/video2 ! videoconvert\"
  A simulated person (the deskstagecam element) watching the shipped monitor video:
  lsydrelight capture --out sim --playlist examples/data/call/monitor.mp4 \\
      --display \"fakesink sync=false\" --camera \"screen. ! queue ! deskstagecam subject=201\"

",
        crate::exit::codes_help!()
    )
)]
pub struct Args {
    /// The capture folder: a new one, or one an earlier capture wrote (a session is added)
    #[arg(long, value_name = "DIR")]
    out: PathBuf,

    /// The webcam, as a gst-launch-1.0 fragment; may read the screen's tee `screen.`
    #[arg(long, value_name = "FRAGMENT", default_value = "v4l2src")]
    camera: String,

    /// The screen, as a gst-launch-1.0 fragment [default: ximagesrc use-damage=false, or
    /// pipewiresrc when WAYLAND_DISPLAY is set]
    #[arg(long, value_name = "FRAGMENT", conflicts_with = "playlist")]
    screen: Option<String>,

    /// Videos to play while recording, one after another; what they show is the screen's
    /// content (no screen grab). The recording ends when they do
    #[arg(long, value_name = "FILE", num_args = 1..)]
    playlist: Vec<PathBuf>,

    /// With --playlist: where the videos are shown, a gst-launch-1.0 sink fragment; make its
    /// window full-screen
    #[arg(
        long,
        value_name = "FRAGMENT",
        default_value = "autovideosink",
        requires = "playlist"
    )]
    display: String,

    /// Stop after this many seconds of recording [default: at Ctrl-C, or the playlist's end]
    #[arg(long, value_name = "N", value_parser = positive_seconds)]
    seconds: Option<f64>,

    /// Mark this session as the one `lsydrelight train` evaluates on (and does not train on)
    #[arg(long)]
    held_out: bool,

    /// Also store the screen itself as screen.mkv. Privacy: that is everything the screen
    /// showed while recording
    #[arg(long)]
    keep_screen: bool,
}

fn positive_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
        _ => Err(format!("`{s}` is not a positive number of seconds")),
    }
}

/// How long the camera may take to deliver its first frame.
const FIRST_FRAME_TIMEOUT: Duration = Duration::from_secs(60);
/// How often the status line is redrawn.
const STATUS_INTERVAL: Duration = Duration::from_millis(250);

pub fn run(args: Args, quiet: bool) -> Status {
    record(&args, quiet).unwrap_or_else(|f| f.report())
}

fn default_screen() -> String {
    if std::env::var_os("WAYLAND_DISPLAY").is_some() {
        "pipewiresrc".into()
    } else {
        "ximagesrc use-damage=false".into()
    }
}

fn fragments(args: &Args) -> Result<Fragments, Failure> {
    for f in &args.playlist {
        if !f.is_file() {
            return Err(Failure::new(format!(
                "--playlist {}: no such file; pass video files",
                f.display()
            )));
        }
    }
    let playlist = (!args.playlist.is_empty()).then(|| Playlist {
        files: args.playlist.clone(),
        display: args.display.clone(),
    });
    let screen = match &playlist {
        Some(p) => format!(
            "playlist: {}",
            p.files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        None => args.screen.clone().unwrap_or_else(default_screen),
    };
    Ok(Fragments {
        camera: args.camera.clone(),
        screen,
        playlist,
    })
}

fn record(args: &Args, quiet: bool) -> Result<Status, Failure> {
    let fragments = fragments(args)?;
    let mut capture = Capture::open(&args.out)?;
    let detector = face_detector()?;
    std::fs::create_dir_all(&args.out).map_err(|e| {
        Failure::new(format!(
            "cannot create the capture folder {}: {e}",
            args.out.display()
        ))
    })?;
    let name = capture.next_session();
    let session_dir = args.out.join(&name);
    let partial = Partial::new(&session_dir);
    let temp = partial.temp().to_path_buf();
    std::fs::create_dir(&temp)
        .map_err(|e| Failure::new(format!("cannot create {}: {e}", temp.display())))?;
    let started = folder::now_rfc3339();
    let pipeline = graph::build(&fragments, &temp, args.keep_screen)?;
    let recorder = Recorder::create(&temp)?;
    record::attach_light(&pipeline, &recorder);
    record::attach_face(&pipeline, &recorder, detector);

    let bars = Bars::new(quiet);
    let status = bars.status_line();
    let end = watch(&pipeline, &recorder, &fragments, args, &bars, &status);
    let _ = pipeline.set_state(gst::State::Null);
    status.finish();
    let end = end?;

    let mut rec = record::lock(&recorder);
    let light_frames = rec.finish(&temp)?;
    if rec.camera_frames == 0 {
        return match end {
            End::Stopped => {
                eprintln!("stopped before the camera delivered a frame: nothing recorded");
                Ok(Status::Interrupted)
            }
            _ => Err(Failure::new(format!(
                "--camera {}: the camera delivered no frames",
                fragments.camera
            ))),
        };
    }
    let summary = rec.guidance.summary().clone();
    let seconds = rec.camera_time.unwrap_or(0.0);
    let session = folder::Session {
        format: folder::SESSION_FORMAT,
        version: folder::VERSION,
        started,
        seconds,
        camera: fragments.camera.clone(),
        screen: fragments.screen.clone(),
        camera_frames: rec.camera_frames,
        light_frames,
        screen_kept: args.keep_screen,
        guidance: serde_json::to_value(&summary).expect("plain data serialises"),
    };
    drop(rec);
    folder::write_json(&temp.join("session.json"), &session)?;
    partial.commit()?;
    capture.add_session(&name, args.held_out)?;
    bars.result(&format!(
        "{} {name}: {:.1} s, {} camera frames ({} usable, {} pairable), {} screen frames{}{} -> {}",
        if end == End::Stopped { "stopped" } else { "ok" },
        seconds,
        session.camera_frames,
        summary.usable_frames,
        summary.pairable_frames,
        light_frames,
        summary.monitor_share.map_or(String::new(), |s| format!(
            ", monitor {:.0} % of the face's light",
            s * 100.0
        )),
        if args.held_out {
            ", held out for evaluation"
        } else {
            ""
        },
        session_dir.display()
    ));
    Ok(if end == End::Stopped {
        Status::Interrupted
    } else {
        Status::Success
    })
}

fn face_detector() -> Result<gstlsydrelight::face::FaceDetector, Failure> {
    let library = gstlsydrelight::paths::default_ort_library();
    let env = gstlsydrelight::engine::environment(&library)
        .map_err(|e| Failure::new(format!("cannot start the face detector: {e}")))?;
    gstlsydrelight::face::FaceDetector::new(env, &gstlsydrelight::paths::default_face_detector(), 1)
        .map_err(|e| Failure::new(format!("cannot start the face detector: {e}")))
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum End {
    /// --seconds reached, or the playlist or a source ended.
    Complete,
    /// Ctrl-C: what was recorded was drained into finished files.
    Stopped,
}

/// Runs the pipeline until --seconds, the end of its sources, or Ctrl-C, with
/// the status line and warnings as it goes.
fn watch(
    pipeline: &gst::Pipeline,
    recorder: &record::Shared,
    fragments: &Fragments,
    args: &Args,
    bars: &Bars,
    status: &StatusLine,
) -> Result<End, Failure> {
    let bus = pipeline
        .bus()
        .ok_or_else(|| Failure::new("internal error: a pipeline without a bus"))?;
    let error = |message: &gst::message::Error| -> Failure {
        if let Some(f) = record::lock(recorder).failure.clone() {
            return f;
        }
        diagnose(pipeline, message, fragments, &args.out)
    };
    if pipeline.set_state(gst::State::Playing).is_err() {
        let message =
            bus.timed_pop_filtered(gst::ClockTime::from_seconds(5), &[gst::MessageType::Error]);
        return Err(match message.as_ref().map(|m| m.view()) {
            Some(gst::MessageView::Error(e)) => error(e),
            _ => Failure::new(format!(
                "the capture pipeline would not start\n  --camera {}\n  --screen {}",
                fragments.camera, fragments.screen
            )),
        });
    }
    let started = Instant::now();
    let mut last_status = Instant::now() - STATUS_INTERVAL;
    let mut stopping: Option<End> = None;
    loop {
        let (camera_time, screen_time, frames, warnings) = {
            let mut r = record::lock(recorder);
            let warnings = r.guidance.take_warnings();
            (r.camera_time, r.screen_time, r.camera_frames, warnings)
        };
        for w in warnings {
            bars.note(&format!("warning at {:.1} s: {}", w.at, w.message));
        }
        if stopping.is_none() {
            let recorded = camera_time.unwrap_or(0.0).max(screen_time.unwrap_or(0.0));
            let reason = if interrupt::stop_requested() {
                Some(End::Stopped)
            } else if args
                .seconds
                .is_some_and(|s| camera_time.is_some_and(|c| c >= s))
            {
                Some(End::Complete)
            } else {
                None
            };
            if let Some(reason) = reason {
                // End-of-stream from the sources, as `gst-launch-1.0 -e` sends: every
                // branch drains and the muxers write their indexes, so the files play.
                pipeline.send_event(gst::event::Eos::new());
                stopping = Some(reason);
            } else if frames == 0 && started.elapsed() > FIRST_FRAME_TIMEOUT {
                return Err(Failure::new(format!(
                    "--camera {}: no camera frame in {} s (screen frames so far: {}); check \
                     that the camera works, e.g. with gst-launch-1.0 {} ! videoconvert ! \
                     autovideosink",
                    fragments.camera,
                    FIRST_FRAME_TIMEOUT.as_secs(),
                    recorded,
                    fragments.camera
                )));
            }
        }
        if last_status.elapsed() >= STATUS_INTERVAL {
            last_status = Instant::now();
            status.say(&status_text(&record::lock(recorder), stopping));
        }
        let Some(message) = bus.timed_pop(gst::ClockTime::from_mseconds(100)) else {
            continue;
        };
        match message.view() {
            gst::MessageView::Eos(_) => return Ok(stopping.unwrap_or(End::Complete)),
            gst::MessageView::Error(e) => return Err(error(e)),
            gst::MessageView::Warning(w) => {
                bars.note(&format!("warning: {}", w.error().message()));
            }
            _ => {}
        }
    }
}

/// The live status line; `stopping` once end-of-stream is on its way.
fn status_text(r: &Recorder, stopping: Option<End>) -> String {
    let s = r.guidance.summary();
    let t = r.camera_time.unwrap_or(0.0);
    let share = match s.monitor_share_recent {
        Some(v) => format!("{:.0} %", v * 100.0),
        None => "measuring".into(),
    };
    format!(
        "{} {:>5.1} s | usable frames {} of {}, pairable {} | monitor's share of face light {} | poses {}/{}{}",
        if stopping.is_some() {
            "finishing"
        } else {
            "REC"
        },
        t,
        s.usable_frames,
        r.camera_frames,
        s.pairable_frames,
        share,
        s.pose_bins_covered,
        s.pose_bins,
        if stopping == Some(End::Stopped) {
            " | Ctrl-C again to abort"
        } else {
            ""
        },
    )
}

/// A pipeline error as a message that names the part at fault and what to do.
fn diagnose(
    pipeline: &gst::Pipeline,
    e: &gst::message::Error,
    fragments: &Fragments,
    out: &Path,
) -> Failure {
    let text = e.error().message().trim_end_matches('.').to_string();
    let detail = e
        .debug()
        .map(|d| {
            d.split_once(":\n")
                .map_or(d.to_string(), |(_, x)| x.to_string())
        })
        .map_or(String::new(), |d| format!(" ({d})"));
    Failure::new(match graph::part_of(pipeline, e.src()) {
        Part::Camera => format!(
            "--camera {}: {text}{detail}; is a webcam connected and free? Pass yours, e.g. \
             --camera \"v4l2src device=/dev/video2\"",
            fragments.camera
        ),
        Part::Screen if fragments.playlist.is_some() => {
            format!("--playlist: {text}{detail}; check that each file plays (gst-play-1.0 FILE)")
        }
        Part::Screen => format!(
            "--screen {}: {text}{detail}; is there a screen to grab? Pass --screen with a \
             source that works here, or --playlist",
            fragments.screen
        ),
        Part::Output => format!(
            "cannot write into {}: {text}{detail}; check that the folder is writable and has room",
            out.display()
        ),
        Part::Other => format!("{text}{detail}"),
    })
}
