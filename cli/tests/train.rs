//! Your own light stage, end to end at tiny scale, as a person runs it:
//! `lsydrelight capture` records the simulator's person (the `deskstagecam`
//! webcam, lit by exactly what the screen branch shows) in two sessions, then
//! `lsydrelight train` trains a model from that folder (200 steps at 32 px), and
//! `lsydrelight relight` relights the held-out session with it through the
//! element. Checks that every stage connects, that the element loads the model,
//! and that bad capture folders fail with their exit codes.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use deskstage::io::write_npy;

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

/// The screen the simulated person watches: white and black frames in turn. At
/// 18 fps, the 6 fps camera films every third frame: white and black in turn too.
const SCREEN: &str = "videotestsrc pattern=blink ! video/x-raw,width=320,height=180,framerate=18/1";
/// The simulated webcam filming that screen's light on the simulator's person, who
/// sits still so that frames of one pose under both lights (the training pairs)
/// come in a few seconds.
const CAMERA: &str =
    "screen. ! queue ! deskstagecam subject=201 motion=frozen width=320 height=240 fps=6";

/// A capture folder recorded by `lsydrelight capture` with the simulated webcam:
/// two sessions, the second held out. This is the light-stage loop as a person
/// runs it, capture to model, at a scale CI affords.
fn capture_folder() -> &'static Path {
    static FOLDER: OnceLock<PathBuf> = OnceLock::new();
    FOLDER.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("train-capture");
        let _ = std::fs::remove_dir_all(&dir);
        let dir_arg = dir.to_str().unwrap();
        for (seconds, extra) in [("6", None), ("4", Some("--held-out"))] {
            let mut args = vec![
                "capture",
                "--out",
                dir_arg,
                "--screen",
                SCREEN,
                "--camera",
                CAMERA,
                "--seconds",
                seconds,
            ];
            args.extend(extra);
            let o = lsydrelight(&args);
            assert_eq!(o.status.code(), Some(0), "capture: {}", text(&o));
        }
        dir
    })
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
        "200",
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
    // The simulator's dome sessions are trained on beside the person's own, and paired.
    assert!(log.contains("4 rehearsal sessions"), "{log}");
    let pairing: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("training/pairing.json")).unwrap())
            .unwrap();
    let rehearsed: Vec<&serde_json::Value> = pairing["sessions"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| {
            s["session"]
                .as_str()
                .unwrap()
                .starts_with("rehearsal-dome-")
        })
        .collect();
    assert_eq!(rehearsed.len(), 4, "{pairing}");
    assert!(
        rehearsed.iter().all(|s| s["pairs"].as_u64().unwrap() > 0),
        "{pairing}"
    );
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
