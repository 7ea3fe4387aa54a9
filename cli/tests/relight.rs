//! `lsydrelight relight` run as a person runs it: the built program on real MP4
//! and MKV files with audio. Checks that audio comes out bit-identical, that
//! Ctrl-C leaves a playable file, and that bad input fails with a clear message,
//! its exit code, and no file under the output's name.

mod media;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use media::{FRAMES, LONG_FRAMES, fixtures};

/// `lsydrelight relight ARGS`, the arguments strings or paths.
macro_rules! relight {
    ($($arg:expr),* $(,)?) => {
        lsydrelight(&[$(AsRef::<OsStr>::as_ref(&$arg)),*])
    };
}

/// The program with this checkout's model unless the test names one: a build
/// in a shared target folder would otherwise find the model of the checkout
/// that holds the folder.
fn lsydrelight(args: &[&OsStr]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_lsydrelight"));
    c.arg("relight").args(args);
    if !args.contains(&OsStr::new("--model")) && !args.contains(&OsStr::new("--help")) {
        c.arg("--model").arg(workspace().join("models/default"));
    }
    c
}

fn run(mut command: Command) -> Output {
    command.output().expect("the program runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Files in `dir` whose names end `.part`: unfinished outputs.
fn partials(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".part"))
        .collect()
}

/// A failed run: exit code 1, a message naming `names`, nothing under the
/// output's name and no unfinished file beside it.
fn assert_fails(o: &Output, out: &Path, names: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "exit code; stderr: {err}");
    for n in names {
        assert!(err.contains(n), "the message names {n:?}: {err}");
    }
    assert!(!out.exists(), "no file under the final name after: {err}");
    assert!(
        partials(out.parent().unwrap()).is_empty(),
        "no partial file left"
    );
}

#[test]
fn mp4_with_screen_relights_video_and_keeps_audio_bit_identical() {
    let f = fixtures();
    let dir = tempfile::tempdir().unwrap();
    let (out, predicted) = (dir.path().join("relit.mp4"), dir.path().join("monitor.mkv"));
    let target = workspace().join("models/targets/sunset.png");
    let o = run(relight!(
        "--face",
        f.face_mp4,
        "--screen",
        f.screen_mp4,
        "--offset",
        "0.05",
        "--target",
        target,
        "--predicted-monitor",
        predicted,
        "--out",
        out,
    ));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stdout(&o).contains(&format!("{FRAMES} frames")),
        "{}",
        stdout(&o)
    );
    assert_eq!(
        media::stream_type(&out, "video/").as_deref(),
        Some("video/x-h264")
    );
    assert_eq!(media::decode_video(&out), (FRAMES, 160, 120));
    let audio = media::audio_packets(&f.face_mp4);
    assert!(audio.len() > 50, "the input has audio");
    assert!(
        media::audio_packets(&out) == audio,
        "AAC packets kept bit for bit"
    );
    assert_eq!(media::decode_video(&predicted), (FRAMES, 256, 128));
    assert!(partials(dir.path()).is_empty());
}

/// A video in which no face is ever found: relit (passed through), and no
/// predicted-monitor file, since it would have no frames and not play.
#[test]
fn no_face_anywhere_writes_no_predicted_monitor_and_says_so() {
    let f = fixtures();
    let dir = tempfile::tempdir().unwrap();
    let (out, predicted) = (dir.path().join("relit.mp4"), dir.path().join("monitor.mp4"));
    // The screen recording: abstract monitor content, nobody in it.
    let o = run(relight!(
        "--face",
        f.screen_mp4,
        "--predicted-monitor",
        predicted,
        "--out",
        out,
    ));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(media::decode_video(&out).0, FRAMES);
    assert!(!predicted.exists());
    assert!(
        stderr(&o).contains("no face was found in any frame"),
        "{}",
        stderr(&o)
    );
    assert!(partials(dir.path()).is_empty());
}

#[test]
fn mkv_keeps_opus_audio_bit_identical() {
    let f = fixtures();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("relit.mkv");
    let o = run(relight!(
        "--face",
        f.face_mkv,
        "--quality",
        "30",
        "--out",
        out
    ));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(
        media::stream_type(&out, "video/").as_deref(),
        Some("video/x-h264")
    );
    assert_eq!(media::decode_video(&out).0, FRAMES);
    let audio = media::audio_packets(&f.face_mkv);
    assert!(audio.len() > 50, "the input has audio");
    assert!(
        media::audio_packets(&out) == audio,
        "Opus packets kept bit for bit"
    );
}

#[test]
fn ctrl_c_stops_cleanly_and_leaves_a_playable_file() {
    let f = fixtures();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("relit.mp4");
    let mut child = relight!("--face", f.long_mp4, "--out", out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Once the muxer has written the first relit frames to the temporary file.
    let started = Instant::now();
    while !partials(dir.path())
        .iter()
        .any(|p| std::fs::metadata(p).is_ok_and(|m| m.len() > 0))
    {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before writing"
        );
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "nothing written in 2 minutes"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(!out.exists(), "the final name appears only at the end");
    // SAFETY: a signal to our own child, which has not been waited for, so its pid is still its.
    let sent = unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
    assert_eq!(sent, 0, "SIGINT sent");
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(partials(dir.path()).is_empty(), "renamed into place");
    let (frames, w, h) = media::decode_video(&out);
    assert!(
        (1..LONG_FRAMES).contains(&frames) && (w, h) == (160, 120),
        "{frames} frames of {w}x{h}: playable, and stopped early"
    );
    let (kept, all) = (
        media::audio_packets(&out),
        media::audio_packets(&f.long_mp4),
    );
    assert!(!kept.is_empty() && kept.len() < all.len());
    assert!(
        kept[..] == all[..kept.len()],
        "the audio so far, bit for bit"
    );
}

#[test]
fn missing_face_file_fails_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("relit.mp4");
    let o = run(relight!(
        "--face",
        dir.path().join("nope.mp4"),
        "--out",
        out
    ));
    assert_fails(&o, &out, &["--face", "nope.mp4", "no such file"]);
}

#[test]
fn file_without_video_fails_naming_it() {
    let f = fixtures();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("relit.mkv");
    let o = run(relight!("--face", f.voice_mkv, "--out", out));
    assert_fails(&o, &out, &["--face", "voice.mkv", "no video stream"]);
}

#[test]
fn file_that_is_no_recording_fails_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let (face, out) = (dir.path().join("notes.mp4"), dir.path().join("relit.mp4"));
    std::fs::write(&face, "minutes of the call, not the call\n".repeat(100)).unwrap();
    let o = run(relight!("--face", face, "--out", out));
    assert_fails(
        &o,
        &out,
        &["--face", "notes.mp4", "not a recording GStreamer can read"],
    );
}

#[test]
fn folder_without_model_fails_before_starting() {
    let f = fixtures();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("relit.mp4");
    let o = run(relight!(
        "--face",
        f.face_mp4,
        "--model",
        dir.path(),
        "--out",
        out
    ));
    assert_fails(&o, &out, &["--model", "model.json"]);
}

/// A model folder that passes the first look (a model.json is there) but that
/// the element cannot load: the failure comes once the pipeline runs, and still
/// leaves nothing behind.
#[test]
fn broken_model_fails_and_leaves_nothing() {
    let f = fixtures();
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model");
    std::fs::create_dir(&model).unwrap();
    std::fs::write(model.join("model.json"), "{}").unwrap();
    let out = dir.path().join("relit.mp4");
    let o = run(relight!(
        "--face", f.face_mp4, "--model", model, "--out", out
    ));
    assert_fails(&o, &out, &["cannot relight", "model.json"]);
}

#[test]
fn usage_errors_exit_2() {
    let f = fixtures();
    let dir = tempfile::tempdir().unwrap();
    let avi = dir.path().join("relit.avi");
    let face = &f.face_mp4;
    for (command, says) in [
        (relight!("--face", face, "--out", avi), ".mp4 or .mkv"),
        (relight!("--face", face), "--out"),
        (
            relight!("--face", face, "--offset", "0.1", "--out", avi),
            "--screen",
        ),
        (
            relight!("--face", face, "--quality", "51", "--out", avi),
            "--quality",
        ),
    ] {
        let o = run(command);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(says), "names {says}: {}", stderr(&o));
    }
    assert!(
        std::fs::read_dir(dir.path()).unwrap().next().is_none(),
        "nothing written"
    );
}

#[test]
fn help_documents_exit_codes() {
    let o = run(relight!("--help"));
    let help = stdout(&o);
    for code in ["0 ", "1 ", "2 ", "130 "] {
        assert!(
            help.contains(&format!("  {code}")),
            "exit code {code}in: {help}"
        );
    }
}

#[test]
fn folder_relights_each_recording_and_reports_each() {
    let f = fixtures();
    let dir = tempfile::tempdir().unwrap();
    let (calls, out) = (dir.path().join("calls"), dir.path().join("relit"));
    std::fs::create_dir(&calls).unwrap();
    std::fs::copy(&f.face_mp4, calls.join("monday.mp4")).unwrap();
    std::fs::copy(&f.face_mkv, calls.join("tuesday.mkv")).unwrap();
    std::fs::copy(&f.voice_mkv, calls.join("wednesday.mkv")).unwrap();
    std::fs::write(calls.join("agenda.txt"), "not a recording").unwrap();
    let o = run(relight!("--face", calls, "--out", out, "--jobs", "2"));
    assert_eq!(
        o.status.code(),
        Some(1),
        "one recording has no video: {}",
        stderr(&o)
    );
    let (report, errors) = (stdout(&o), stderr(&o));
    for name in ["monday.mp4", "tuesday.mkv"] {
        let line = report
            .lines()
            .find(|l| l.contains(name))
            .unwrap_or_else(|| panic!("{report}"));
        assert!(line.starts_with("ok") && line.contains(" fps"), "{line}");
    }
    assert!(
        errors.lines().any(|l| l.starts_with("failed")
            && l.contains("wednesday.mkv")
            && l.contains("no video")),
        "{errors}"
    );
    assert!(!report.contains("agenda") && !errors.contains("agenda"));
    assert_eq!(media::decode_video(&out.join("monday.mp4")).0, FRAMES);
    assert_eq!(media::decode_video(&out.join("tuesday.mkv")).0, FRAMES);
    assert!(!out.join("wednesday.mkv").exists());
    assert!(partials(&out).is_empty());
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}
