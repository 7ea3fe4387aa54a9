//! `deskstage`: writes the simulator's datasets, recordings and contact sheet.
//!
//! ```text
//! deskstage captures  --out DIR [--sessions N] [--seconds S] [--fps F] [--seed N] [--subject N] [--stage desk|dome]
//!                     [--content capture|stage]  (what the monitor shows; by default videos on the desk, lights under the dome)
//! deskstage paired    --out DIR [--poses N] [--lights N] [--subject N]
//! deskstage heldout   --out DIR [--subject N] [--stage desk|dome]  (the test set: 9 poses x 9 lights)
//! deskstage validation --out DIR [--subject N]  (the same for choosing models; never the test set)
//! deskstage absent    --out DIR [--frames N]   (the empty desk: the person away)
//! deskstage recording --out DIR --name steady|slow|cuts|walkaway|call [--frames N] [--width W --height H]
//! deskstage sheet     --out FILE.png [--subject N]
//! deskstage targets   --out DIR      (the target monitor lights as PNG: studio, sunset, left-key)
//! deskstage speed                    (prints the renderer's timings)
//! deskstage all       --out DIR      (everything the trainer and benchmarks read)
//! ```

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use deskstage::content::Style;
use deskstage::dataset::{self, CaptureSpec, Recording, RecordingSpec, Stage, TestSet};
use deskstage::subject::DEFAULT_SUBJECT_SEED;

struct Args {
    command: String,
    flags: HashMap<String, String>,
}

impl Args {
    fn parse() -> Result<Args, String> {
        let mut it = std::env::args().skip(1);
        let command = it
            .next()
            .ok_or("missing command; see the top of src/bin/deskstage.rs")?;
        let mut flags = HashMap::new();
        while let Some(k) = it.next() {
            let key = k
                .strip_prefix("--")
                .ok_or(format!("unexpected argument {k}"))?;
            let v = it.next().ok_or(format!("--{key} needs a value"))?;
            flags.insert(key.to_string(), v);
        }
        Ok(Args { command, flags })
    }

    fn out(&self) -> Result<PathBuf, String> {
        self.flags
            .get("out")
            .map(PathBuf::from)
            .ok_or("--out is required".into())
    }

    fn num<T: std::str::FromStr>(&self, key: &str, default: T) -> Result<T, String> {
        match self.flags.get(key) {
            Some(v) => v.parse().map_err(|_| format!("--{key}: cannot parse {v}")),
            None => Ok(default),
        }
    }
}

fn captures(out: &Path, spec: &CaptureSpec) -> Result<(), String> {
    for s in 0..spec.sessions {
        let t = Instant::now();
        let dir = out.join(format!("session-{s:03}"));
        dataset::write_capture(&dir, spec, s).map_err(|e| format!("{}: {e}", dir.display()))?;
        let frames = (spec.seconds * spec.fps).round();
        eprintln!(
            "capture session {s}: {frames} frames in {:.1} s ({:.1} ms/frame)",
            t.elapsed().as_secs_f64(),
            1e3 * t.elapsed().as_secs_f64() / frames
        );
    }
    Ok(())
}

fn recording(out: &Path, spec: RecordingSpec) -> Result<(), String> {
    let t = Instant::now();
    let name = spec.name.clone();
    let frames = spec.frames;
    let rec = Recording::new(spec)?;
    rec.write(&out.join(&name))
        .map_err(|e| format!("{name}: {e}"))?;
    eprintln!(
        "recording {name}: {frames} frames with {} ground-truth targets in {:.1} s",
        rec.targets.len(),
        t.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Times the renderer: the per-pose precompute, one light, each further light
/// in a batch, and whole recordings.
fn speed() -> Result<(), String> {
    use deskstage::content::Playlist;
    use deskstage::material::Look;
    use deskstage::monitor::CellLight;
    use deskstage::render::{Renderer, Scene};
    use deskstage::subject::{State, Subject};
    let ms = |t: Instant| 1e3 * t.elapsed().as_secs_f64();
    println!(
        "| frame | per-pose precompute ms | one light ms | each further light ms (batch of 8) |"
    );
    println!("|---|---|---|---|");
    let playlist = Playlist::random(1, "speed", 10.0, Style::Capture);
    let lights: Vec<CellLight> = (0..8)
        .map(|i| CellLight::from_frame(&playlist.frame(i as f64), 16, 32))
        .collect();
    let refs: Vec<&CellLight> = lights.iter().collect();
    for (w, h) in [(256, 256), (480, 360), (640, 480)] {
        let r = Renderer::new(Scene::new(Subject::default(), w, h))?;
        let (mut pre, mut one, mut eight) = (f64::MAX, f64::MAX, f64::MAX);
        for i in 0..5 {
            let mut st = State::default();
            st.pose.yaw = 0.05 * i as f32;
            let t = Instant::now();
            let tr = r.prepare(&Look::default(), &st);
            pre = pre.min(ms(t));
            let t = Instant::now();
            r.render(&tr, &refs[..1]);
            one = one.min(ms(t));
            let t = Instant::now();
            r.render(&tr, &refs);
            eight = eight.min(ms(t));
        }
        println!(
            "| {w}x{h} | {pre:.1} | {one:.1} | {:.1} |",
            (eight - one) / 7.0
        );
    }
    println!();
    println!(
        "| recording (300 frames, 480x360) | seconds, face only | seconds, with 3 ground-truth targets |"
    );
    println!("|---|---|---|");
    for name in ["steady", "cuts"] {
        let rec = Recording::standard(name).ok_or("no such recording")?;
        let t = Instant::now();
        for i in 0..rec.spec.frames {
            rec.frame(i, false);
        }
        let face = t.elapsed().as_secs_f64();
        let t = Instant::now();
        for i in 0..rec.spec.frames {
            rec.frame(i, true);
        }
        println!("| {name} | {face:.1} | {:.1} |", t.elapsed().as_secs_f64());
    }
    Ok(())
}

fn run(a: &Args) -> Result<(), String> {
    let subject = a.num("subject", DEFAULT_SUBJECT_SEED)?;
    let spec = CaptureSpec {
        subject_seed: subject,
        seed: a.num("seed", 1)?,
        sessions: a.num("sessions", CaptureSpec::default().sessions)?,
        seconds: a.num("seconds", CaptureSpec::default().seconds)?,
        fps: a.num("fps", CaptureSpec::default().fps)?,
        size: a.num("size", dataset::CAPTURE_SIZE)?,
        stage: Stage::from_name(a.flags.get("stage").map_or("desk", String::as_str))?,
        content: a
            .flags
            .get("content")
            .map(|name| Style::of_capture(name))
            .transpose()?,
    };
    let io = |e: std::io::Error| e.to_string();
    match a.command.as_str() {
        "captures" => captures(&a.out()?, &spec),
        "paired" => {
            dataset::write_paired(&a.out()?, &spec, a.num("poses", 600)?, a.num("lights", 4)?)
                .map_err(io)
        }
        "heldout" => {
            dataset::write_test_set(&a.out()?, TestSet::Heldout, subject, spec.size, spec.stage)
                .map_err(io)
        }
        "validation" => dataset::write_test_set(
            &a.out()?,
            TestSet::Validation,
            subject,
            spec.size,
            spec.stage,
        )
        .map_err(io),
        "absent" => dataset::write_absent(&a.out()?, &spec, a.num("frames", 400)?).map_err(io),
        "recording" => {
            let name: String = a.num("name", String::new())?;
            let mut r = RecordingSpec::standard(&name).ok_or(format!(
                "--name must be one of {:?}",
                RecordingSpec::STANDARD
            ))?;
            r.subject_seed = subject;
            r.frames = a.num("frames", r.frames)?;
            r.width = a.num("width", r.width)?;
            r.height = a.num("height", r.height)?;
            r.display_latency = a.num("latency", r.display_latency)?;
            recording(&a.out()?, r)
        }
        "targets" => {
            let out = a.out()?;
            std::fs::create_dir_all(&out).map_err(io)?;
            for (name, clip) in deskstage::content::target_clips() {
                let frame = deskstage::content::Playlist::still(clip).frame(0.0);
                deskstage::io::write_png(&out.join(format!("{name}.png")), &frame).map_err(io)?;
            }
            Ok(())
        }
        "sheet" => {
            let sheet = deskstage::sheet::contact_sheet(subject, a.num("cell", 192)?)?;
            deskstage::io::write_png(&a.out()?, &sheet).map_err(io)
        }
        "all" => {
            let out = a.out()?;
            captures(&out.join("captures"), &spec)?;
            dataset::write_paired(&out.join("paired"), &spec, a.num("poses", 600)?, 4)
                .map_err(io)?;
            for set in [TestSet::Heldout, TestSet::Validation] {
                dataset::write_test_set(&out.join(set.name()), set, subject, spec.size, spec.stage)
                    .map_err(io)?;
            }
            dataset::write_absent(&out.join("absent"), &spec, a.num("absent", 400)?).map_err(io)?;
            for name in RecordingSpec::STANDARD {
                let mut r = RecordingSpec::standard(name).expect("standard recording");
                r.subject_seed = subject;
                recording(&out.join("recordings"), r)?;
            }
            let sheet = deskstage::sheet::contact_sheet(subject, 192)?;
            deskstage::io::write_png(&out.join("contact-sheet.png"), &sheet).map_err(io)
        }
        "speed" => speed(),
        other => Err(format!("unknown command {other}")),
    }
}

fn main() -> ExitCode {
    match Args::parse().and_then(|a| run(&a)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("deskstage: {e}");
            ExitCode::FAILURE
        }
    }
}
