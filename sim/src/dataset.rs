//! Datasets and recordings: what the trainer reads and the tests replay.
//!
//! - Training captures have the form a real LSYD capture has: face frames,
//!   the monitor frames shown at the same times, timestamps, and 2D facial
//!   keypoints. `truth.npy` holds the simulator's true pose and expression,
//!   for measuring keypoint pairing; training never reads it.
//! - Paired ground truth: the same pose and expression under several lights.
//! - The held-out set: 9 pose-expression combinations under 9 monitor
//!   lights, 36 source-target pairs per pose, 324 in all.
//! - Test recordings: a face video and its monitor video as ordinary `.y4m`
//!   files, with the exact ground truth of the video relit to target lights.
//!
//! Every output is a pure function of its seeds.

use std::fs;
use std::io;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::content::{self, Clip, FRAME_HEIGHT, FRAME_WIDTH, Playlist, Style};
use crate::material::{Ambient, AmbientKind, Look, NEUTRAL};
use crate::math::Vec3;
use crate::mesh::landmarks_3d;
use crate::monitor::{CellLight, MonitorGeometry, RgbImage};
use crate::motion::{Range, Trajectory, Waypoint};
use crate::render::{Renderer, Scene, Sensor};
use crate::rng::{Rng, hash, label};
use crate::subject::{Expression, Pose, State, Subject};

/// Side of the square head-and-shoulders frames of captures and the held-out set.
pub const CAPTURE_SIZE: usize = 256;
/// Number of facial keypoints (the iBUG 68-point layout).
pub const KEYPOINTS: usize = 68;
/// Values per row of `truth.npy`.
pub const TRUTH_FIELDS: [&str; 10] = [
    "yaw_deg",
    "pitch_deg",
    "roll_deg",
    "tx_m",
    "ty_m",
    "tz_m",
    "mouth_open",
    "smile",
    "blink",
    "present",
];

fn truth_row(s: &State) -> [f32; 10] {
    let p = &s.pose;
    let e = &s.expression;
    [
        p.yaw.to_degrees(),
        p.pitch.to_degrees(),
        p.roll.to_degrees(),
        p.translation.x,
        p.translation.y,
        p.translation.z,
        e.mouth_open,
        e.smile,
        e.blink,
        p.present as u8 as f32,
    ]
}

/// Image coordinates of the 68 keypoints, NaN when the person is not in view.
pub fn keypoints(r: &Renderer, state: &State) -> Vec<[f32; 2]> {
    match landmarks_3d(&r.scene.subject, state) {
        Some(pts) => pts
            .iter()
            .map(|p| {
                let (x, y, _) = r.scene.camera.project(*p);
                [x, y]
            })
            .collect(),
        None => vec![[f32::NAN; 2]; KEYPOINTS],
    }
}

/// Still frames of clips and their cell lights.
pub(crate) fn still_lights(r: &Renderer, clips: &[Clip]) -> (Vec<RgbImage>, Vec<CellLight>) {
    let shown: Vec<RgbImage> = clips
        .iter()
        .map(|c| Playlist::still(c.clone()).frame(0.0))
        .collect();
    let cells = shown.iter().map(|f| light_of(r, f)).collect();
    (shown, cells)
}

/// Where a dataset's monitor lights shine from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Stage {
    /// The desk's screen: what an at-home capture records.
    #[default]
    Desk,
    /// The dome the light code stands for (`MonitorGeometry::dome`): the
    /// grid's pictures as lights from up to 90 degrees to each side, showing a
    /// light stage's lights (`Style::Stage`), where the starter model learns
    /// which side a light comes from.
    Dome,
}

impl Stage {
    pub fn from_name(name: &str) -> Result<Stage, String> {
        match name {
            "desk" => Ok(Stage::Desk),
            "dome" => Ok(Stage::Dome),
            _ => Err(format!("--stage {name}: one of desk or dome")),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Stage::Desk => "desk",
            Stage::Dome => "dome",
        }
    }

    fn is_desk(&self) -> bool {
        *self == Stage::Desk
    }

    /// What a capture session on this stage shows: videos on the desk, a
    /// light stage's lights under the dome.
    pub fn style(self) -> Style {
        match self {
            Stage::Desk => Style::Capture,
            Stage::Dome => Style::Stage,
        }
    }

    pub fn monitor(self) -> MonitorGeometry {
        match self {
            Stage::Desk => MonitorGeometry::default(),
            Stage::Dome => MonitorGeometry::dome(),
        }
    }
}

/// The renderer of captures and the held-out set: a square camera at the desk,
/// its monitor's lights on `stage`.
fn square_renderer(subject_seed: u64, size: usize, stage: Stage) -> io::Result<Renderer> {
    let mut scene = Scene::new(Subject::from_seed(subject_seed), size, size);
    scene.monitor = stage.monitor();
    Renderer::new(scene).map_err(io::Error::other)
}

/// The monitor's cell light for a frame it shows.
pub fn light_of(r: &Renderer, frame: &RgbImage) -> CellLight {
    CellLight::from_frame(frame, r.scene.monitor.rows, r.scene.monitor.cols)
}

fn write_json(path: &Path, value: &impl Serialize) -> io::Result<()> {
    fs::write(
        path,
        serde_json::to_string_pretty(value).map_err(io::Error::other)? + "\n",
    )
}

/// Settings of the training captures.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CaptureSpec {
    pub subject_seed: u64,
    pub seed: u64,
    pub sessions: usize,
    pub seconds: f64,
    /// Frames kept per second of capture.
    pub fps: f64,
    pub size: usize,
    /// Where the monitor's light shines from (desk when a spec predates it).
    #[serde(default, skip_serializing_if = "Stage::is_desk")]
    pub stage: Stage,
    /// What the monitor shows, when not what `stage` shows by default
    /// ([`Stage::style`]): a light stage's lights at the desk teach the lights
    /// the presets make there, one bright area on a dark screen.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub content: Option<Style>,
}

impl CaptureSpec {
    /// What the monitor shows in this spec's sessions.
    pub fn style(&self) -> Style {
        self.content.unwrap_or(self.stage.style())
    }
}

impl Default for CaptureSpec {
    fn default() -> Self {
        CaptureSpec {
            subject_seed: crate::subject::DEFAULT_SUBJECT_SEED,
            seed: 1,
            sessions: 16,
            seconds: 60.0,
            fps: 10.0,
            size: CAPTURE_SIZE,
            stage: Stage::Desk,
            content: None,
        }
    }
}

#[derive(Serialize)]
struct CaptureMeta<'a> {
    kind: &'static str,
    spec: &'a CaptureSpec,
    session: usize,
    frames: usize,
    outfit: String,
    ambient: String,
    keypoint_layout: &'static str,
    truth_fields: [&'static str; 10],
    monitor_frame: [usize; 2],
}

/// Writes one capture session: `face.npy`, `monitor.npy`, `timestamps.npy`,
/// `keypoints.npy`, `truth.npy` and `meta.json` in `dir`.
pub fn write_capture(dir: &Path, spec: &CaptureSpec, session: usize) -> io::Result<()> {
    fs::create_dir_all(dir)?;
    let r = square_renderer(spec.subject_seed, spec.size, spec.stage)?;
    let domain = format!("train-{session}");
    let look = Look::random(spec.seed, &domain);
    let motion = Trajectory::random(
        spec.seed,
        &format!("{domain}-motion"),
        spec.seconds,
        Range::CAPTURE,
        0.6,
    );
    let playlist = Playlist::random(
        spec.seed,
        &format!("{domain}-monitor"),
        spec.seconds,
        spec.style(),
    );
    let frames = (spec.seconds * spec.fps).round() as usize;
    let sensor = Sensor::default();
    let noise_seed = hash(spec.seed, &[label(&domain)]);

    let s = spec.size;
    let mut face = crate::io::NpyWriter::<u8>::create(&dir.join("face.npy"), &[frames, s, s, 3])?;
    let mut monitor = crate::io::NpyWriter::<u8>::create(
        &dir.join("monitor.npy"),
        &[frames, FRAME_HEIGHT, FRAME_WIDTH, 3],
    )?;
    let mut times = Vec::with_capacity(frames);
    let mut kps = Vec::with_capacity(frames * KEYPOINTS * 2);
    let mut truth = Vec::with_capacity(frames * 10);
    for i in 0..frames {
        let t = i as f64 / spec.fps;
        let state = motion.state(t);
        let shown = playlist.frame(t);
        let transport = r.prepare(&look, &state);
        let img = r.render(&transport, &[&light_of(&r, &shown)]).remove(0);
        face.append(&sensor.capture(&img, noise_seed, i as u64).data)?;
        monitor.append(&shown.data)?;
        times.push(t);
        kps.extend(keypoints(&r, &state).into_iter().flatten());
        truth.extend(truth_row(&state));
    }
    face.finish()?;
    monitor.finish()?;
    crate::io::write_npy(&dir.join("timestamps.npy"), &[frames], &times)?;
    crate::io::write_npy(&dir.join("keypoints.npy"), &[frames, KEYPOINTS, 2], &kps)?;
    crate::io::write_npy(&dir.join("truth.npy"), &[frames, 10], &truth)?;
    write_json(
        &dir.join("meta.json"),
        &CaptureMeta {
            kind: "capture",
            spec,
            session,
            frames,
            outfit: format!("{:?}", look.outfit),
            ambient: format!("{:?}", look.ambient),
            keypoint_layout: "iBUG 300-W 68 points, image pixels (x, y), NaN when nobody is in view",
            truth_fields: TRUTH_FIELDS,
            monitor_frame: [FRAME_HEIGHT, FRAME_WIDTH],
        },
    )
}

/// Writes `poses` poses from training-like motion, each under `lights` monitor
/// lights: `face.npy` (poses, lights, S, S, 3), `monitor.npy`, `keypoints.npy`, `truth.npy`.
pub fn write_paired(dir: &Path, spec: &CaptureSpec, poses: usize, lights: usize) -> io::Result<()> {
    fs::create_dir_all(dir)?;
    let r = square_renderer(spec.subject_seed, spec.size, spec.stage)?;
    let s = spec.size;
    let sensor = Sensor::default();
    let mut face =
        crate::io::NpyWriter::<u8>::create(&dir.join("face.npy"), &[poses, lights, s, s, 3])?;
    let mut monitor = crate::io::NpyWriter::<u8>::create(
        &dir.join("monitor.npy"),
        &[poses, lights, FRAME_HEIGHT, FRAME_WIDTH, 3],
    )?;
    let mut kps = Vec::new();
    let mut truth = Vec::new();
    let motion = Trajectory::random(
        spec.seed,
        "paired-motion",
        poses as f64 * 0.7 + 1.0,
        Range::CAPTURE,
        0.0,
    );
    let mut rng = Rng::stream(spec.seed, "paired-lights");
    for i in 0..poses {
        let state = motion.state(i as f64 * 0.7);
        let look = Look::random(spec.seed, &format!("paired-{}", i % 8));
        let shown: Vec<RgbImage> = (0..lights)
            .map(|_| Playlist::still(Clip::random(&mut rng)).frame(0.0))
            .collect();
        let cells: Vec<CellLight> = shown.iter().map(|f| light_of(&r, f)).collect();
        let refs: Vec<&CellLight> = cells.iter().collect();
        let transport = r.prepare(&look, &state);
        for (m, img) in r.render(&transport, &refs).iter().enumerate() {
            face.append(
                &sensor
                    .capture(
                        img,
                        hash(spec.seed, &[label("paired")]),
                        (i * lights + m) as u64,
                    )
                    .data,
            )?;
            monitor.append(&shown[m].data)?;
        }
        kps.extend(keypoints(&r, &state).into_iter().flatten());
        truth.extend(truth_row(&state));
    }
    face.finish()?;
    monitor.finish()?;
    crate::io::write_npy(&dir.join("keypoints.npy"), &[poses, KEYPOINTS, 2], &kps)?;
    crate::io::write_npy(&dir.join("truth.npy"), &[poses, 10], &truth)
}

/// Writes `frames` webcam frames of the empty desk (the person away) under random
/// monitor content and room light: `face.npy` (frames, S, S, 3).
pub fn write_absent(dir: &Path, spec: &CaptureSpec, frames: usize) -> io::Result<()> {
    fs::create_dir_all(dir)?;
    let r = square_renderer(spec.subject_seed, spec.size, spec.stage)?;
    let s = spec.size;
    let mut face = crate::io::NpyWriter::<u8>::create(&dir.join("face.npy"), &[frames, s, s, 3])?;
    let mut rng = Rng::stream(spec.seed, "absent");
    let away = State {
        pose: Pose {
            present: false,
            ..Pose::default()
        },
        expression: Expression::default(),
    };
    for i in 0..frames {
        let look = Look::random(spec.seed, &format!("absent-{}", i % 16));
        let shown = Playlist::still(Clip::random(&mut rng)).frame(0.0);
        let transport = r.prepare(&look, &away);
        let img = r.render(&transport, &[&light_of(&r, &shown)]).remove(0);
        face.append(
            &Sensor::default()
                .capture(&img, hash(spec.seed, &[label("absent")]), i as u64)
                .data,
        )?;
    }
    face.finish()
}

/// The nine held-out pose-expression combinations. None lies on a training
/// trajectory: they are fixed here, not drawn from the training streams.
pub fn heldout_states() -> Vec<State> {
    let pose = |yaw: f32, pitch: f32, roll: f32, t: (f32, f32, f32)| Pose {
        yaw: yaw.to_radians(),
        pitch: pitch.to_radians(),
        roll: roll.to_radians(),
        translation: Vec3::new(t.0, t.1, t.2),
        body: Vec3::ZERO,
        present: true,
    };
    let ex = |mouth_open: f32, smile: f32, blink: f32| Expression {
        mouth_open,
        smile,
        blink,
    };
    vec![
        State {
            pose: pose(0.0, 0.0, 0.0, (0.0, 0.0, 0.0)),
            expression: ex(0.0, 0.0, 0.0),
        },
        State {
            pose: pose(22.0, 3.0, 2.0, (0.01, 0.0, 0.02)),
            expression: ex(0.0, 0.6, 0.0),
        },
        State {
            pose: pose(-24.0, -4.0, -3.0, (-0.015, 0.01, -0.03)),
            expression: ex(0.5, 0.0, 0.0),
        },
        State {
            pose: pose(5.0, 11.0, 0.0, (0.0, -0.015, 0.04)),
            expression: ex(0.2, 0.3, 0.0),
        },
        State {
            pose: pose(-8.0, -12.0, 4.0, (0.02, 0.02, 0.0)),
            expression: ex(0.0, 0.0, 0.0),
        },
        State {
            pose: pose(14.0, -6.0, -6.0, (-0.02, 0.0, 0.06)),
            expression: ex(0.7, 0.2, 0.0),
        },
        State {
            pose: pose(-16.0, 8.0, 6.0, (0.0, -0.02, -0.06)),
            expression: ex(0.0, 0.9, 0.0),
        },
        State {
            pose: pose(28.0, -2.0, 1.0, (0.03, 0.01, 0.01)),
            expression: ex(0.3, 0.0, 0.0),
        },
        State {
            pose: pose(-3.0, 4.0, -7.0, (-0.03, -0.01, 0.03)),
            expression: ex(0.0, 0.0, 0.0),
        },
    ]
}

/// The held-out set's room and outfit: a capture the model never saw.
pub fn heldout_look() -> Look {
    let mut look = Look::random(11, "heldout-look");
    look.ambient = Ambient {
        kind: AmbientKind::Ceiling,
        tint: NEUTRAL,
        ratio: 0.18,
    };
    look
}

/// Nine poses of the validation set, drawn from their own stream: never on a
/// training trajectory, and not the held-out set's.
pub fn validation_states(subject_seed: u64) -> Vec<State> {
    let mut r = Rng::stream(subject_seed, "validation-poses");
    (0..9)
        .map(|_| State {
            pose: Pose {
                yaw: r.range(-25.0, 25.0).to_radians(),
                pitch: r.range(-12.0, 12.0).to_radians(),
                roll: r.range(-6.0, 6.0).to_radians(),
                translation: Vec3::new(
                    r.range(-0.03, 0.03),
                    r.range(-0.02, 0.02),
                    r.range(-0.06, 0.06),
                ),
                body: Vec3::ZERO,
                present: true,
            },
            expression: Expression {
                mouth_open: if r.chance(0.4) {
                    r.range(0.1, 0.7)
                } else {
                    0.0
                },
                smile: if r.chance(0.4) {
                    r.range(0.2, 0.9)
                } else {
                    0.0
                },
                blink: 0.0,
            },
        })
        .collect()
}

/// The two fixed sets of 9 poses under 9 lights. Choices made while developing
/// (the default model's width and resolution) are made on `Validation`, so the
/// `Heldout` test set is never tuned to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TestSet {
    Heldout,
    Validation,
}

impl TestSet {
    pub fn name(self) -> &'static str {
        match self {
            TestSet::Heldout => "heldout",
            TestSet::Validation => "validation",
        }
    }

    fn contents(self, subject_seed: u64) -> (Vec<State>, Vec<Clip>, Look) {
        match self {
            TestSet::Heldout => (
                heldout_states(),
                content::heldout_clips(subject_seed),
                heldout_look(),
            ),
            TestSet::Validation => (
                validation_states(subject_seed),
                content::validation_clips(subject_seed),
                Look::random(13, "validation-look"),
            ),
        }
    }
}

/// Writes a test set: `images.npy` (9 poses, 9 lights, S, S, 3) as the
/// webcam records them, `clean.npy` the same without sensor noise (exact
/// ground truth), `monitor.npy` (9, H, W, 3), `keypoints.npy` and `truth.npy`.
pub fn write_test_set(
    dir: &Path,
    set: TestSet,
    subject_seed: u64,
    size: usize,
    stage: Stage,
) -> io::Result<()> {
    fs::create_dir_all(dir)?;
    let r = square_renderer(subject_seed, size, stage)?;
    let (states, clips, look) = set.contents(subject_seed);
    let (shown, cells) = still_lights(&r, &clips);
    let refs: Vec<&CellLight> = cells.iter().collect();
    let (np, nl) = (states.len(), refs.len());
    let sensor = Sensor::default();
    let mut noisy =
        crate::io::NpyWriter::<u8>::create(&dir.join("images.npy"), &[np, nl, size, size, 3])?;
    let mut clean =
        crate::io::NpyWriter::<u8>::create(&dir.join("clean.npy"), &[np, nl, size, size, 3])?;
    let mut kps = Vec::new();
    let mut truth = Vec::new();
    for (p, state) in states.iter().enumerate() {
        let transport = r.prepare(&look, state);
        for (l, img) in r.render(&transport, &refs).iter().enumerate() {
            noisy.append(
                &sensor
                    .capture(
                        img,
                        hash(subject_seed, &[label(set.name())]),
                        (p * nl + l) as u64,
                    )
                    .data,
            )?;
            clean.append(&sensor.clean(img).data)?;
        }
        kps.extend(keypoints(&r, state).into_iter().flatten());
        truth.extend(truth_row(state));
    }
    noisy.finish()?;
    clean.finish()?;
    let mut mon = Vec::with_capacity(nl * FRAME_WIDTH * FRAME_HEIGHT * 3);
    for f in &shown {
        mon.extend_from_slice(&f.data);
    }
    crate::io::write_npy(
        &dir.join("monitor.npy"),
        &[nl, FRAME_HEIGHT, FRAME_WIDTH, 3],
        &mon,
    )?;
    crate::io::write_npy(&dir.join("keypoints.npy"), &[np, KEYPOINTS, 2], &kps)?;
    crate::io::write_npy(&dir.join("truth.npy"), &[np, 10], &truth)?;
    write_json(
        &dir.join("meta.json"),
        &serde_json::json!({
            "kind": set.name(),
            "subject_seed": subject_seed,
            "poses": np,
            "lights": nl,
            "pairs": np * nl * (nl - 1) / 2,
            "size": size,
            "images": "webcam frames (sensor noise), the inputs",
            "clean": "the same frames without sensor noise: exact ground truth",
            "truth_fields": TRUTH_FIELDS,
        }),
    )
}

/// What a test recording shows, and how it is filmed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordingSpec {
    pub name: String,
    pub subject_seed: u64,
    pub seed: u64,
    pub frames: usize,
    pub fps: u32,
    pub width: usize,
    pub height: usize,
    /// Monitor content: steady, slowly changing or with scene cuts.
    pub style: String,
    /// Seconds (start, end) during which the person is away.
    pub away: Option<(f64, f64)>,
    /// Seconds between the monitor showing a frame and its light reaching the
    /// recorded face (display plus camera latency).
    pub display_latency: f64,
    /// A walk about the room instead of sitting at the desk (`wander`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<Vec<Waypoint>>,
    /// Where the target lights of the ground truth shine from: the desk's
    /// screen, as the person's own monitor does, or the dome the light code
    /// stands for. The person is always filmed at the desk.
    #[serde(default, skip_serializing_if = "Stage::is_desk")]
    pub truth_stage: Stage,
}

/// `wander`'s walk: from the left of the frame to its middle, nearer; to the right
/// and farther; out of the frame on the right. Out of sight (away, 6.5 s to 7.5 s)
/// the person goes round to the left, and walks back in to the left of the middle.
const WANDER: [Waypoint; 10] = [
    Waypoint {
        t: 0.0,
        yaw_deg: 12.0,
        body: [-0.22, 0.02, 0.05],
    },
    Waypoint {
        t: 0.8,
        yaw_deg: 12.0,
        body: [-0.22, 0.02, 0.05],
    },
    Waypoint {
        t: 2.3,
        yaw_deg: -5.0,
        body: [-0.02, 0.0, -0.14],
    },
    Waypoint {
        t: 3.0,
        yaw_deg: -5.0,
        body: [-0.02, 0.0, -0.14],
    },
    Waypoint {
        t: 4.6,
        yaw_deg: -15.0,
        body: [0.22, 0.04, 0.22],
    },
    Waypoint {
        t: 5.3,
        yaw_deg: -15.0,
        body: [0.22, 0.04, 0.22],
    },
    Waypoint {
        t: 6.5,
        yaw_deg: -20.0,
        body: [0.85, -0.02, 0.25],
    },
    Waypoint {
        t: 7.5,
        yaw_deg: 20.0,
        body: [-0.85, 0.0, 0.10],
    },
    Waypoint {
        t: 8.7,
        yaw_deg: 8.0,
        body: [-0.12, 0.01, 0.0],
    },
    Waypoint {
        t: 10.0,
        yaw_deg: 8.0,
        body: [-0.12, 0.01, 0.0],
    },
];

impl RecordingSpec {
    /// The standard recordings: `steady`, `slow`, `cuts`, `walkaway`, `call`, the
    /// mixed one the demo relights, and `wander`, the person walking about the
    /// frame and out of it. 300 frames at 30 fps, 480×360 (`wander` 640×360).
    pub fn standard(name: &str) -> Option<RecordingSpec> {
        let (style, away) = match name {
            "steady" => ("steady", None),
            "slow" => ("slow", None),
            "cuts" => ("cuts", None),
            "walkaway" => ("capture", Some((4.0, 6.5))),
            "call" => ("capture", Some((7.5, 8.5))),
            "wander" => ("capture", Some((6.5, 7.5))),
            _ => return None,
        };
        let wander = name == "wander";
        Some(RecordingSpec {
            name: name.into(),
            subject_seed: crate::subject::DEFAULT_SUBJECT_SEED,
            seed: label(name),
            frames: 300,
            fps: 30,
            width: if wander { 640 } else { 480 },
            height: 360,
            style: style.into(),
            away,
            display_latency: 0.0,
            path: wander.then(|| WANDER.to_vec()),
            truth_stage: Stage::Desk,
        })
    }

    pub const STANDARD: [&'static str; 6] =
        ["steady", "slow", "cuts", "walkaway", "call", "wander"];

    fn style(&self) -> Style {
        match self.style.as_str() {
            "steady" => Style::Steady,
            "slow" => Style::Slow,
            "cuts" => Style::Cuts,
            _ => Style::Capture,
        }
    }
}

/// One frame of a recording with everything known about it.
pub struct RecordedFrame {
    pub time: f64,
    pub state: State,
    /// What the webcam recorded (with sensor noise).
    pub face: RgbImage,
    /// The same frame without sensor noise: the face under the source light
    /// exactly, for telling what in an error comes from the camera's noise.
    pub clean_face: RgbImage,
    /// What the monitor showed at this time (the screen capture's frame).
    pub monitor: RgbImage,
    /// The exact, noiseless frame relit to each target light, in target order.
    pub ground_truth: Vec<RgbImage>,
}

/// A test recording, rendered on demand.
pub struct Recording {
    pub spec: RecordingSpec,
    renderer: Renderer,
    /// The renderer of the target lights' ground truth when they shine from
    /// elsewhere than the desk (`RecordingSpec::truth_stage`).
    truth_renderer: Option<Renderer>,
    look: Look,
    motion: Trajectory,
    playlist: Playlist,
    /// Target lights: name, the monitor frame that defines it, its cells.
    pub targets: Vec<(String, RgbImage, CellLight)>,
}

impl Recording {
    pub fn new(spec: RecordingSpec) -> Result<Recording, String> {
        let scene = Scene::new(
            Subject::from_seed(spec.subject_seed),
            spec.width,
            spec.height,
        );
        let truth_renderer = match spec.truth_stage {
            Stage::Desk => None,
            stage => Some(Renderer::new(Scene {
                monitor: stage.monitor(),
                ..scene.clone()
            })?),
        };
        let renderer = Renderer::new(scene)?;
        let seconds = spec.frames as f64 / spec.fps as f64;
        let mut motion = Trajectory::random(
            spec.seed,
            "recording-motion",
            seconds + 1.0,
            Range::CALL,
            0.4,
        );
        if let Some(path) = &spec.path {
            motion = motion.along(path);
        }
        if let Some((a, b)) = spec.away {
            motion = motion.with_absence(a, b);
        }
        let playlist =
            Playlist::random(spec.seed, "recording-monitor", seconds + 1.0, spec.style());
        let targets = content::target_clips()
            .into_iter()
            .map(|(name, clip)| {
                let frame = Playlist::still(clip).frame(0.0);
                let cells = light_of(&renderer, &frame);
                (name.to_string(), frame, cells)
            })
            .collect();
        Ok(Recording {
            look: Look::random(spec.seed, "recording-look"),
            spec,
            renderer,
            truth_renderer,
            motion,
            playlist,
            targets,
        })
    }

    pub fn standard(name: &str) -> Option<Recording> {
        RecordingSpec::standard(name).and_then(|s| Recording::new(s).ok())
    }

    pub fn time(&self, frame: usize) -> f64 {
        frame as f64 / self.spec.fps as f64
    }

    /// The person's pose and expression at frame `i`, without rendering it.
    pub fn state(&self, i: usize) -> State {
        self.motion.state(self.time(i))
    }

    /// The monitor frame shown at time `t`.
    pub fn monitor_frame(&self, t: f64) -> RgbImage {
        self.playlist.frame(t)
    }

    /// True when the monitor content cuts between frames `i - 1` and `i`.
    pub fn cut_before(&self, i: usize) -> bool {
        i > 0 && self.playlist.cut_between(self.time(i - 1), self.time(i))
    }

    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Renders frame `i`: the recorded face, the monitor frame, and ground truth
    /// for the targets (all of them when `with_truth`, none otherwise).
    pub fn frame(&self, i: usize, with_truth: bool) -> RecordedFrame {
        let t = self.time(i);
        let state = self.state(i);
        let monitor = self.monitor_frame(t);
        let lit_by = self.monitor_frame((t - self.spec.display_latency).max(0.0));
        let source = light_of(&self.renderer, &lit_by);
        let mut lights = vec![&source];
        let targets = self.targets.iter().map(|(_, _, c)| c);
        let transport = self.renderer.prepare(&self.look, &state);
        let truth_apart = match &self.truth_renderer {
            Some(truth) if with_truth => {
                let transport = truth.prepare(&self.look, &state);
                truth.render(&transport, &targets.collect::<Vec<_>>())
            }
            _ => {
                if with_truth {
                    lights.extend(targets);
                }
                Vec::new()
            }
        };
        let mut imgs = self
            .renderer
            .render(&transport, &lights)
            .into_iter()
            .chain(truth_apart);
        let sensor = Sensor::default();
        let lit = imgs.next().unwrap();
        let face = sensor.capture(&lit, self.spec.seed, i as u64);
        RecordedFrame {
            time: t,
            state,
            face,
            clean_face: sensor.clean(&lit),
            monitor,
            ground_truth: imgs.map(|img| sensor.clean(&img)).collect(),
        }
    }

    /// Writes `face.y4m` (4:2:0, as a webcam), `monitor.y4m` (4:4:4, as a
    /// lossless screen capture), one `truth-<target>.y4m` (4:4:4) per target,
    /// the target monitor frames as PNG, and `meta.json`.
    pub fn write(&self, dir: &Path) -> io::Result<()> {
        use crate::io::{Chroma, Y4mWriter};
        fs::create_dir_all(dir)?;
        let s = &self.spec;
        let mut face = Y4mWriter::create(
            &dir.join("face.y4m"),
            s.width,
            s.height,
            s.fps,
            Chroma::C420,
        )?;
        let mut monitor = Y4mWriter::create(
            &dir.join("monitor.y4m"),
            FRAME_WIDTH,
            FRAME_HEIGHT,
            s.fps,
            Chroma::C444,
        )?;
        let mut truth = self
            .targets
            .iter()
            .map(|(name, _, _)| {
                Y4mWriter::create(
                    &dir.join(format!("truth-{name}.y4m")),
                    s.width,
                    s.height,
                    s.fps,
                    Chroma::C444,
                )
            })
            .collect::<io::Result<Vec<_>>>()?;
        for i in 0..s.frames {
            let f = self.frame(i, true);
            face.write(&f.face)?;
            monitor.write(&f.monitor)?;
            for (w, gt) in truth.iter_mut().zip(&f.ground_truth) {
                w.write(gt)?;
            }
        }
        face.finish()?;
        monitor.finish()?;
        for w in truth {
            w.finish()?;
        }
        for (name, frame, _) in &self.targets {
            crate::io::write_png(&dir.join(format!("target-{name}.png")), frame)?;
        }
        let cuts: Vec<usize> = (1..s.frames).filter(|&i| self.cut_before(i)).collect();
        write_json(
            &dir.join("meta.json"),
            &serde_json::json!({
                "kind": "recording",
                "spec": s,
                "targets": self.targets.iter().map(|(n, _, _)| n).collect::<Vec<_>>(),
                "cuts_before_frames": cuts,
                "colour": "BT.601 limited range; truth files are the exact noiseless frames",
            }),
        )
    }
}
