//! `lsydrelight capture` run as a person runs it: the built program records a
//! simulated person (the `deskstagecam` element, filming the screen branch)
//! watching a blinking screen, into a real capture folder. Checks the folder
//! against CAPTURE-LAYOUT.md, that no screen content is stored unless asked,
//! that the guidance warns when it should (and not otherwise), that Ctrl-C
//! leaves a usable session, and that bad input fails clearly.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use deskstage::io::read_npy;
use gst::prelude::*;

/// The screen: white and black frames in turn, so the monitor's light on the
/// face swings and its share can be measured in a few seconds. At 18 fps, the
/// 6 fps camera films every third frame: white and black in turn too.
const SCREEN: &str = "videotestsrc pattern=blink ! video/x-raw,width=320,height=180,framerate=18/1";

/// The simulated webcam filming the screen branch, small and slow to render fast.
fn camera(extra: &str) -> String {
    format!("screen. ! queue ! deskstagecam subject=201 width=240 height=180 fps=6 {extra}")
}

fn capture(out: &Path, seconds: Option<&str>, camera_extra: &str, flags: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_lsydrelight"));
    c.arg("capture")
        .arg("--out")
        .arg(out)
        .args(["--screen", SCREEN, "--camera", &camera(camera_extra)])
        .args(flags);
    if let Some(s) = seconds {
        c.args(["--seconds", s]);
    }
    c
}

fn run(mut command: Command) -> Output {
    command.output().expect("the program runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn warning_kinds(session: &serde_json::Value) -> Vec<String> {
    session["guidance"]["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["kind"].as_str().unwrap().to_string())
        .collect()
}

/// Decodes a video file: its frames' timestamps in seconds, and its size.
fn decode(path: &Path) -> (Vec<f64>, (i32, i32)) {
    gst::init().unwrap();
    let pipeline = gst::parse::launch(&format!(
        "filesrc location=\"{}\" ! decodebin ! videoconvert ! appsink name=sink sync=false",
        path.display()
    ))
    .unwrap()
    .downcast::<gst::Pipeline>()
    .unwrap();
    let sink = pipeline
        .by_name("sink")
        .and_downcast::<gst_app::AppSink>()
        .unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let (mut times, mut size) = (Vec::new(), (0, 0));
    while let Some(sample) = sink.try_pull_sample(gst::ClockTime::from_seconds(60)) {
        let s = sample.caps().unwrap().structure(0).unwrap().to_owned();
        size = (s.get("width").unwrap(), s.get("height").unwrap());
        let pts = sample.buffer().unwrap().pts().unwrap();
        times.push(pts.nseconds() as f64 / 1e9);
    }
    let error = pipeline
        .bus()
        .and_then(|b| b.pop_filtered(&[gst::MessageType::Error]));
    pipeline.set_state(gst::State::Null).unwrap();
    assert!(error.is_none(), "{} plays: {error:?}", path.display());
    (times, size)
}

/// A session as the layout says: session.json, camera.mkv with its frames at
/// running times, light.npy and light-times.npy of the same length on the same
/// clock. Returns session.json.
fn check_session(dir: &Path) -> serde_json::Value {
    let s = json(&dir.join("session.json"));
    assert_eq!(s["format"], "lsydrelight-capture-session");
    assert_eq!(s["version"], 1);
    assert!(s["started"].as_str().unwrap().ends_with('Z'));
    let (times, size) = decode(&dir.join("camera.mkv"));
    assert_eq!(size, (240, 180));
    assert_eq!(times.len() as u64, s["camera_frames"].as_u64().unwrap());
    assert!(times.len() >= 6, "{} camera frames", times.len());
    assert!(times.windows(2).all(|w| w[1] > w[0]), "{times:?}");
    assert!(
        times[0] < 0.5,
        "running time from the session's start: {times:?}"
    );
    let (shape, light) = read_npy::<f32>(&dir.join("light.npy")).unwrap();
    let (tshape, light_times) = read_npy::<f64>(&dir.join("light-times.npy")).unwrap();
    let m = s["light_frames"].as_u64().unwrap() as usize;
    assert_eq!(shape, [m, 3, 16, 32]);
    assert_eq!(tshape, [m]);
    assert!(
        light.iter().all(|v| (0.0..=1.0).contains(v)),
        "linear light"
    );
    assert!(light_times.windows(2).all(|w| w[1] >= w[0]));
    assert!(light_times[0] < 0.5);
    // Every camera frame has a screen frame at or before it.
    assert!(light_times[0] <= times[0] && *light_times.last().unwrap() >= times[times.len() - 2]);
    let seconds = s["seconds"].as_f64().unwrap();
    assert!(
        (seconds - times.last().unwrap()).abs() < 0.5,
        "{seconds} vs {times:?}"
    );
    s
}

/// The blinking screen's light: whole frames of white and of black, both recorded.
fn assert_blinks(session: &Path) {
    let (_, light) = read_npy::<f32>(&session.join("light.npy")).unwrap();
    let frame_means: Vec<f32> = light
        .chunks(3 * 16 * 32)
        .map(|f| f.iter().sum::<f32>() / f.len() as f32)
        .collect();
    assert!(frame_means.iter().any(|&v| v > 0.99) && frame_means.iter().any(|&v| v < 0.01));
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn sessions_append_with_camera_and_light_but_no_screen_unless_asked() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("me");
    let o = run(capture(&out, Some("4"), "", &[]));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let first = check_session(&out.join("session-000"));
    assert_blinks(&out.join("session-000"));
    // No screen content on disk: only the camera, the light grid and the metadata.
    assert_eq!(
        files_in(&out.join("session-000")),
        ["camera.mkv", "light-times.npy", "light.npy", "session.json"]
    );
    assert_eq!(first["screen_kept"], false);
    assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
    assert_eq!(warning_kinds(&first), Vec::<String>::new());
    let g = &first["guidance"];
    let frames = first["camera_frames"].as_u64().unwrap();
    assert!(
        g["usable_frames"].as_u64().unwrap() * 10 >= frames * 8,
        "{g}"
    );
    let share = g["monitor_share"].as_f64().unwrap();
    assert!(share > 0.6, "the monitor dominates a dim room: {share}");

    // The second call appends, held out, keeping the screen, in a bright room.
    let o = run(capture(
        &out,
        Some("4"),
        "room-light=3",
        &["--held-out", "--keep-screen"],
    ));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let index = json(&out.join("capture.json"));
    assert_eq!(index["format"], "lsydrelight-capture");
    assert_eq!(index["version"], 1);
    assert_eq!(
        index["sessions"],
        serde_json::json!(["session-000", "session-001"])
    );
    assert_eq!(index["held_out"], "session-001");
    let second = check_session(&out.join("session-001"));
    assert_eq!(second["screen_kept"], true);
    let (screen_times, size) = decode(&out.join("session-001/screen.mkv"));
    assert_eq!(size, (320, 180));
    assert_eq!(
        screen_times.len() as u64,
        second["light_frames"].as_u64().unwrap()
    );
    assert!(stderr(&o).contains("overpowers"), "{}", stderr(&o));
    assert_eq!(warning_kinds(&second), ["room-overpowers-monitor"]);
    let share = second["guidance"]["monitor_share"].as_f64().unwrap();
    assert!(share < 0.4, "{share}");
}

#[test]
fn a_frozen_pose_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("me");
    let o = run(capture(&out, Some("4"), "motion=frozen", &[]));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("barely changed"), "{}", stderr(&o));
    assert_eq!(
        warning_kinds(&json(&out.join("session-000/session.json"))),
        ["pose-frozen"]
    );
}

/// The shipped call's screen content: what a person sees in a video call.
fn call_file(name: &str) -> String {
    let call = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/call");
    format!(
        "filesrc location=\"{}\" ! decodebin",
        call.join(name).display()
    )
}

#[test]
fn holding_still_while_the_screen_changes_gives_pairable_frames() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("me");
    let o = run({
        let mut c = Command::new(env!("CARGO_BIN_EXE_lsydrelight"));
        c.args(["capture", "--out"]).arg(&out).args([
            "--seconds",
            "4",
            "--screen",
            &call_file("monitor.mp4"),
            "--camera",
            "screen. ! queue ! deskstagecam subject=201 motion=frozen width=320 height=240 fps=6",
        ]);
        c
    });
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let g = &json(&out.join("session-000/session.json"))["guidance"];
    let (usable, pairable) = (
        g["usable_frames"].as_u64().unwrap(),
        g["pairable_frames"].as_u64().unwrap(),
    );
    assert!(usable >= 20 && pairable * 2 >= usable, "{g}");
}

/// A webcam video and a screen recording made by other tools, started together,
/// become a session by naming the files as the sources.
#[test]
fn recordings_made_elsewhere_are_captured_from_their_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("me");
    let o = run({
        let mut c = Command::new(env!("CARGO_BIN_EXE_lsydrelight"));
        c.args(["capture", "--out"]).arg(&out).args([
            "--camera",
            &call_file("face.mp4"),
            "--screen",
            &call_file("monitor.mp4"),
        ]);
        c
    });
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let s = json(&out.join("session-000/session.json"));
    // The shipped call: 10 s at 30 fps, the person away for a second of it.
    assert_eq!(s["camera_frames"], 300);
    assert_eq!(s["light_frames"], 300);
    let usable = s["guidance"]["usable_frames"].as_u64().unwrap();
    assert!((255..=275).contains(&usable), "{usable}");
    let (times, size) = decode(&out.join("session-000/camera.mkv"));
    assert_eq!((times.len(), size), (300, (480, 360)));
}

#[test]
fn a_face_that_leaves_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("me");
    let o = run(capture(&out, Some("3"), "away-after=1", &[]));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("no face for"), "{}", stderr(&o));
    let s = json(&out.join("session-000/session.json"));
    assert_eq!(warning_kinds(&s), ["face-lost"]);
    let g = &s["guidance"];
    assert!(
        g["usable_frames"].as_u64() < g["camera_frames"].as_u64(),
        "{g}"
    );
    assert!(g["face_lost_seconds"].as_f64().unwrap() > 1.0, "{g}");
}

#[test]
fn ctrl_c_ends_the_session_cleanly_and_keeps_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("me");
    let mut child = capture(&out, None, "", &[])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Once the camera file being written holds a few frames.
    let started = Instant::now();
    let written = || -> bool {
        std::fs::read_dir(&out)
            .into_iter()
            .flatten()
            .flatten()
            .any(|e| std::fs::metadata(e.path().join("camera.mkv")).is_ok_and(|m| m.len() > 20_000))
    };
    while !written() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the capture ended by itself"
        );
        assert!(
            started.elapsed() < Duration::from_secs(180),
            "nothing recorded in 3 minutes"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        !out.join("session-000").exists(),
        "the session appears only when finished"
    );
    // SAFETY: a signal to our own child, which has not been waited for, so its pid is still its.
    assert_eq!(
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) },
        0
    );
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    check_session(&out.join("session-000"));
    assert_eq!(
        json(&out.join("capture.json"))["sessions"],
        serde_json::json!(["session-000"])
    );
    assert_eq!(
        files_in(&out),
        ["capture.json", "session-000"],
        "no unfinished files left"
    );
}

#[test]
fn bad_input_fails_with_a_clear_message_and_records_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("me");
    let cases: Vec<(Vec<String>, &[&str])> = vec![
        (
            vec!["--camera".into(), "nosuchelement ! queue".into()],
            &["does not parse", "nosuchelement"],
        ),
        (
            vec![
                "--camera".into(),
                "v4l2src device=/dev/no-such-camera".into(),
            ],
            &["--camera v4l2src device=/dev/no-such-camera", "webcam"],
        ),
    ];
    for (args, words) in cases {
        let o = run({
            let mut c = Command::new(env!("CARGO_BIN_EXE_lsydrelight"));
            c.arg("capture")
                .arg("--out")
                .arg(&out)
                .args(["--screen", SCREEN, "--seconds", "2"]);
            c.args(&args);
            c
        });
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        for w in words {
            assert!(err.contains(w), "{args:?}: names {w:?}: {err}");
        }
        let left: Vec<String> = files_in(&out);
        assert!(left.is_empty(), "{args:?} left {left:?}");
    }

    let file = dir.path().join("a-file");
    std::fs::write(&file, "x").unwrap();
    let o = run(capture(&file, Some("2"), "", &[]));
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("a file, not a folder"),
        "{}",
        stderr(&o)
    );

    let newer = dir.path().join("newer");
    std::fs::create_dir(&newer).unwrap();
    std::fs::write(
        newer.join("capture.json"),
        r#"{"format": "lsydrelight-capture", "version": 9, "sessions": [], "held_out": null}"#,
    )
    .unwrap();
    let o = run(capture(&newer, Some("2"), "", &[]));
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert!(
        err.contains("capture.json") && err.contains("version 9"),
        "{err}"
    );
    assert_eq!(files_in(&newer), ["capture.json"]);
}

/// Encodes one second (15 frames) of a solid test pattern into `path`.
fn clip(path: &Path, pattern: &str, size: (u32, u32), mux: &str) {
    gst::init().unwrap();
    let pipeline = gst::parse::launch(&format!(
        "videotestsrc num-buffers=15 pattern={pattern} ! video/x-raw,width={},height={},\
         framerate=15/1 ! videoconvert ! x264enc ! {mux} ! filesink location=\"{}\"",
        size.0,
        size.1,
        path.display()
    ))
    .unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let bus = pipeline.bus().unwrap();
    let end = bus.timed_pop_filtered(
        gst::ClockTime::from_seconds(60),
        &[gst::MessageType::Eos, gst::MessageType::Error],
    );
    pipeline.set_state(gst::State::Null).unwrap();
    assert!(matches!(
        end.map(|m| m.type_()),
        Some(gst::MessageType::Eos)
    ));
}

#[test]
fn a_playlist_is_played_in_turn_and_is_the_screen_content() {
    let dir = tempfile::tempdir().unwrap();
    let (white, red) = (dir.path().join("white.mp4"), dir.path().join("red.mkv"));
    clip(&white, "white", (320, 180), "mp4mux");
    clip(&red, "red", (160, 120), "matroskamux");
    let out = dir.path().join("me");
    let o = run({
        let mut c = Command::new(env!("CARGO_BIN_EXE_lsydrelight"));
        c.arg("capture")
            .arg("--out")
            .arg(&out)
            .arg("--playlist")
            .arg(&white)
            .arg(&red);
        c.args(["--display", "fakesink sync=false", "--camera", &camera("")]);
        c
    });
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let s = check_session(&out.join("session-000"));
    assert!(
        s["screen"].as_str().unwrap().starts_with("playlist: "),
        "{s}"
    );
    // One second of white, then one of red: a 4:3 video letterboxed into the 16:9
    // screen, as a full-screen player shows it, so its side columns are black.
    let (shape, light) = read_npy::<f32>(&out.join("session-000/light.npy")).unwrap();
    let (_, times) = read_npy::<f64>(&out.join("session-000/light-times.npy")).unwrap();
    assert_eq!(shape[0], 30, "every frame of both videos");
    assert!((times[29] - 29.0 / 15.0).abs() < 0.01, "{times:?}");
    let cell = |frame: usize, channel: usize, col: usize| {
        light[((frame * 3 + channel) * 16 + 8) * 32 + col]
    };
    assert!((cell(0, 1, 0) - 1.0).abs() < 0.01, "white at first");
    assert!(
        (cell(29, 0, 16) - 1.0).abs() < 0.05,
        "red in the middle at the end"
    );
    assert!(
        cell(29, 1, 16) < 0.02 && cell(29, 0, 0) < 0.02,
        "black borders"
    );
    assert_eq!(s["camera_frames"].as_u64(), Some(12), "6 fps for 2 s");
}
