//! `lsydrelight train` run as a person runs it, at tiny scale: a capture folder
//! in the layout `lsydrelight capture` writes (two sessions of the simulator's
//! person at their desk, the camera encoded by x264 into Matroska with the
//! capture clock's timestamps, the screen's light grid from the plugin's own
//! monitor-light code), trained for a few steps at 32 px. Checks that every
//! stage connects, that the element loads the model it writes and relights
//! with it, and that bad capture folders fail with their exit codes.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use deskstage::dataset::{Recording, RecordingSpec};
use deskstage::io::write_npy;
use deskstage::motion::Waypoint;
use gst::prelude::*;
use gstlsydrelight::frame::Frame;
use gstlsydrelight::light::{LIGHT_COLS, LIGHT_ROWS, Light};

const FPS: u32 = 10;
const WIDTH: usize = 320;
const HEIGHT: usize = 240;

fn lsydrelight(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lsydrelight"))
        .args(args)
        .output()
        .expect("the program runs")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A capture folder of two sessions, `frames` each; the second is held out.
fn capture_folder() -> &'static Path {
    static FOLDER: OnceLock<PathBuf> = OnceLock::new();
    FOLDER.get_or_init(|| {
        gst::init().expect("GStreamer initialises");
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("train-capture");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("fixture folder");
        for (i, frames) in [(0usize, 50usize), (1, 24)] {
            write_session(&dir.join(format!("session-00{i}")), 100 + i as u64, frames);
        }
        write_json(
            &dir.join("capture.json"),
            serde_json::json!({"format": "lsydrelight-capture", "version": 1,
                "sessions": ["session-000", "session-001"], "held_out": "session-001"}),
        );
        dir
    })
}

fn write_json(path: &Path, value: serde_json::Value) {
    std::fs::write(path, serde_json::to_string_pretty(&value).unwrap()).expect("writes json");
}

/// One session: the simulator's person sitting still at the desk while the
/// screen cuts between scenes every 0.4 to 1.5 s, so frames of one pose under
/// different lights (the training pairs) come in a few seconds.
fn write_session(dir: &Path, seed: u64, frames: usize) {
    std::fs::create_dir_all(dir).expect("session folder");
    let mut spec = RecordingSpec::standard("cuts").expect("a standard recording");
    let still = |t: f64| Waypoint {
        t,
        yaw_deg: 6.0,
        body: [0.0, 0.0, 0.0],
    };
    spec.path = Some(vec![still(0.0), still(60.0)]);
    spec.seed = seed;
    spec.frames = frames;
    spec.fps = FPS;
    spec.width = WIDTH;
    spec.height = HEIGHT;
    let rec = Recording::new(spec).expect("the simulator renders");
    let rendered: Vec<_> = (0..frames).map(|i| rec.frame(i, false)).collect();
    let mut lights = Vec::new();
    for f in &rendered {
        let m = &f.monitor;
        lights.extend(Light::from_frame(&Frame::packed_rgb(&m.data, m.width, m.height)).0);
    }
    let times: Vec<f64> = (0..frames).map(|i| rec.time(i)).collect();
    write_npy(
        &dir.join("light.npy"),
        &[frames, 3, LIGHT_ROWS, LIGHT_COLS],
        &lights,
    )
    .expect("light.npy");
    write_npy(&dir.join("light-times.npy"), &[frames], &times).expect("light-times.npy");
    encode(
        &dir.join("camera.mkv"),
        rendered.iter().map(|f| f.face.data.clone()),
    );
    write_json(
        &dir.join("session.json"),
        serde_json::json!({"format": "lsydrelight-capture-session", "version": 1,
            "started": format!("2026-11-29T10:0{seed}:00Z"), "seconds": frames as f64 / FPS as f64,
            "camera": "appsrc (test)", "screen": "appsrc (test)", "camera_frames": frames,
            "light_frames": frames, "screen_kept": false, "guidance": {}}),
    );
}

/// RGB frames to H.264 (x264) in Matroska, timestamps from 0 at `FPS`.
fn encode(path: &Path, frames: impl Iterator<Item = Vec<u8>>) {
    let pipeline = gst::parse::launch(&format!(
        "appsrc name=src format=time caps=video/x-raw,format=RGB,width={WIDTH},height={HEIGHT},framerate={FPS}/1 \
         ! videoconvert ! x264enc speed-preset=ultrafast ! matroskamux ! filesink location={}",
        path.display()
    ))
    .expect("encode pipeline")
    .downcast::<gst::Pipeline>()
    .expect("a pipeline");
    pipeline.set_state(gst::State::Playing).expect("plays");
    let src = pipeline
        .by_name("src")
        .and_downcast::<gst_app::AppSrc>()
        .expect("appsrc");
    let frame_ns = 1_000_000_000 / FPS as u64;
    for (i, data) in frames.enumerate() {
        let mut buffer = gst::Buffer::from_slice(data);
        let b = buffer.get_mut().expect("writable");
        b.set_pts(gst::ClockTime::from_nseconds(i as u64 * frame_ns));
        b.set_duration(gst::ClockTime::from_nseconds(frame_ns));
        src.push_buffer(buffer)
            .expect("the encoder takes the frame");
    }
    src.end_of_stream().expect("end of stream");
    let bus = pipeline.bus().expect("bus");
    let msg = bus
        .timed_pop_filtered(
            gst::ClockTime::from_seconds(60),
            &[gst::MessageType::Eos, gst::MessageType::Error],
        )
        .expect("the encoder finishes");
    assert!(matches!(msg.view(), gst::MessageView::Eos(_)), "{msg:?}");
    pipeline.set_state(gst::State::Null).expect("stops");
}

/// A copy of the fixture folder, changed by `edit`, for a bad-input case.
fn broken_copy(name: &str, edit: impl FnOnce(&Path)) -> PathBuf {
    let src = capture_folder();
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("train-broken-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    copy_dir(src, &dir);
    edit(&dir);
    dir
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let dest = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

#[test]
fn train_makes_a_model_the_element_relights_with() {
    let capture = capture_folder();
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("train-model");
    let _ = std::fs::remove_dir_all(&out);
    let capture_arg = capture.to_str().unwrap();
    let out_arg = out.to_str().unwrap();
    let o = lsydrelight(&[
        "train",
        "--capture",
        capture_arg,
        "--out",
        out_arg,
        "--scratch",
        "--resolution",
        "32",
        "--device",
        "cpu",
        // One thread: on a machine shared with other work, two contend for little gain.
        "--threads",
        "1",
        "--steps",
        "20",
    ]);
    let log = text(&o);
    assert_eq!(o.status.code(), Some(0), "{log}");
    for stage in 1..=7 {
        assert!(
            log.contains(&format!("[{stage}/7]")),
            "stage {stage} reported: {log}"
        );
    }
    assert!(log.contains("training pairs"), "pairs reported: {log}");
    assert!(log.contains("the element loads"), "{log}");

    // The model: the contract's manifest and stages, the saved network, the measures.
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("model.json")).unwrap()).unwrap();
    assert_eq!(manifest["resolution"], 32);
    assert_eq!(
        manifest["crop"]["side"].as_f64().map(|v| v as f32),
        Some(2.9)
    );
    assert!(out.join("network.pt").is_file());
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let self_rmse = metrics["self_relight_rmse"]["levels"].as_f64().unwrap();
    assert!(self_rmse.is_finite() && self_rmse > 0.0, "{metrics}");
    assert!(metrics["temporal"]["ratio"].as_f64().unwrap().is_finite());
    assert!(metrics["monitor"]["mae"].as_f64().unwrap().is_finite());
    assert!(
        std::fs::read_to_string(out.join("README.md"))
            .unwrap()
            .contains("lsydrelight train")
    );
    let sheet = std::fs::read(out.join("sheet.png")).unwrap();
    assert!(sheet.starts_with(b"\x89PNG"), "sheet.png is a PNG");

    // The element loads the model (model-location) and relights the held-out camera with it.
    let relit = out.join("relit.mkv");
    let r = lsydrelight(&[
        "relight",
        "--face",
        capture.join("session-001/camera.mkv").to_str().unwrap(),
        "--model",
        out_arg,
        "--out",
        relit.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    assert!(std::fs::metadata(&relit).unwrap().len() > 0);
}

#[test]
fn bad_capture_folders_fail_with_what_is_wrong() {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("train-bad-out");
    let out_arg = out.to_str().unwrap();
    let fails = |capture: &Path, names: &[&str]| {
        let o = lsydrelight(&[
            "train",
            "--capture",
            capture.to_str().unwrap(),
            "--out",
            out_arg,
            "--scratch",
        ]);
        let log = text(&o);
        assert_eq!(o.status.code(), Some(1), "{log}");
        for n in names {
            assert!(log.contains(n), "names {n}: {log}");
        }
    };
    let newer = broken_copy("version", |d| {
        let p = d.join("capture.json");
        let s = std::fs::read_to_string(&p).unwrap();
        std::fs::write(&p, s.replace("\"version\": 1", "\"version\": 7")).unwrap();
    });
    fails(&newer, &["capture.json", "version 7"]);
    let no_camera = broken_copy("camera", |d| {
        std::fs::remove_file(d.join("session-000/camera.mkv")).unwrap()
    });
    fails(&no_camera, &["session-000/camera.mkv"]);
    let no_screen = broken_copy("screen", |d| {
        write_npy(
            &d.join("session-001/light.npy"),
            &[0, 3, 16, 32],
            &[0f32; 0],
        )
        .unwrap();
        write_npy(&d.join("session-001/light-times.npy"), &[0], &[0f64; 0]).unwrap();
    });
    fails(&no_screen, &["session-001", "no screen frames"]);
    fails(&out.join("nowhere"), &["nowhere", "no such folder"]);

    // Usage errors: exit 2.
    let usage = lsydrelight(&["train", "--out", out_arg]);
    assert_eq!(usage.status.code(), Some(2), "{}", text(&usage));
    let both = lsydrelight(&[
        "train",
        "--capture",
        "x",
        "--out",
        out_arg,
        "--scratch",
        "--from",
        "y",
    ]);
    assert_eq!(both.status.code(), Some(2), "{}", text(&both));
    // No starter model where --from points: exit 1, naming the folder and --scratch.
    let capture = capture_folder().to_str().unwrap();
    let no_starter = lsydrelight(&[
        "train",
        "--capture",
        capture,
        "--out",
        out_arg,
        "--from",
        out_arg,
    ]);
    assert_eq!(no_starter.status.code(), Some(1), "{}", text(&no_starter));
    assert!(text(&no_starter).contains("network.pt"));
}
