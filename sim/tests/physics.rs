//! What the desk light stage must get right: linearity, determinism, the
//! physics of light from the monitor, keypoints, and files that reload.

use deskstage::content::{Playlist, Style};
use deskstage::dataset::{self, CaptureSpec, Recording, RecordingSpec, keypoints};
use deskstage::io::{Y4mReader, read_npy};
use deskstage::material::Look;
use deskstage::math::Vec3;
use deskstage::monitor::{CellLight, MonitorGeometry, RgbImage};
use deskstage::render::{LinearImage, Renderer, Scene, Sensor};
use deskstage::rng::Rng;
use deskstage::subject::{Expression, Pose, State, Subject};

const ROWS: usize = 16;
const COLS: usize = 32;

fn renderer(w: usize, h: usize) -> Renderer {
    Renderer::new(Scene::new(Subject::default(), w, h)).unwrap()
}

fn light(f: impl Fn(usize, usize) -> Vec3) -> CellLight {
    let mut l = CellLight::uniform(ROWS, COLS, Vec3::ZERO);
    for r in 0..ROWS {
        for c in 0..COLS {
            l.rgb[r * COLS + c] = f(r, c);
        }
    }
    l
}

fn luminance(img: &LinearImage, x: f32, y: f32, radius: i32) -> f32 {
    let mut s = 0.0;
    let mut n = 0.0;
    for dy in -radius..=radius {
        for dx in -radius..=radius {
            let (px, py) = ((x as i32 + dx) as usize, (y as i32 + dy) as usize);
            let v = img.rgb[py * img.width + px];
            s += 0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z;
            n += 1.0;
        }
    }
    s / n
}

#[test]
fn light_transport_superposes() {
    let r = renderer(96, 96);
    let mut st = State::default();
    st.pose.yaw = 0.3;
    st.expression.mouth_open = 0.5;
    let t = r.prepare(&Look::default(), &st);
    let l1 = light(|row, c| Vec3::new((row + c) as f32 / 48.0, 0.2, 0.5 * (c % 3) as f32));
    let l2 = light(|row, _| Vec3::new(0.1, row as f32 / 16.0, 0.3));
    let sum = l1.add(&l2);
    let out = r.render(&t, &[&l1, &l2, &sum]);
    let amb = r.ambient(&t);
    let mut worst = 0.0f32;
    for i in 0..amb.rgb.len() {
        let lhs = out[2].rgb[i] - amb.rgb[i];
        let rhs = out[0].rgb[i] + out[1].rgb[i] - amb.rgb[i] * 2.0;
        let d = (lhs - rhs).length();
        worst = worst.max(d);
    }
    // Float rounding only: far below one 8-bit step of a linear sensor (1/255).
    assert!(worst < 1e-5, "superposition off by {worst}");
}

#[test]
fn black_monitor_leaves_the_room_light_only() {
    let r = renderer(96, 96);
    let t = r.prepare(&Look::default(), &State::default());
    let black = CellLight::uniform(ROWS, COLS, Vec3::ZERO);
    assert_eq!(r.render(&t, &[&black])[0], r.ambient(&t));
}

#[test]
fn same_seed_same_bytes_across_runs_and_thread_counts() {
    let render_with = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let r = renderer(128, 96);
                let mut st = State::default();
                st.pose.yaw = -0.2;
                let t = r.prepare(&Look::random(3, "det"), &st);
                let l = CellLight::from_frame(
                    &Playlist::random(3, "det", 5.0, deskstage::content::Style::Capture).frame(1.3),
                    ROWS,
                    COLS,
                );
                Sensor::default().capture(&r.render(&t, &[&l])[0], 42, 7)
            })
    };
    let one = render_with(1);
    assert_eq!(one, render_with(1), "the same run twice");
    assert_eq!(one, render_with(2), "one thread and two");
    assert_eq!(one, render_with(3), "one thread and three");
}

/// Cheek positions in the image from the keypoints: image left (subject's right) and image right.
fn cheeks(r: &Renderer, st: &State) -> ((f32, f32), (f32, f32)) {
    let k = keypoints(r, st);
    let mid = |a: usize, b: usize| ((k[a][0] + k[b][0]) / 2.0, (k[a][1] + k[b][1]) / 2.0);
    (mid(3, 31), mid(13, 35))
}

#[test]
fn light_from_one_side_of_the_screen_lights_that_side_of_the_face() {
    let r = renderer(256, 256);
    let st = State::default();
    let t = r.prepare(&Look::default(), &st);
    // Column 0 is the screen's left as the user sees it: the user's left, image right.
    let screen_left = light(|_, c| {
        if c < COLS / 2 {
            Vec3::new(1.0, 1.0, 1.0)
        } else {
            Vec3::ZERO
        }
    });
    let screen_right = light(|_, c| {
        if c >= COLS / 2 {
            Vec3::new(1.0, 1.0, 1.0)
        } else {
            Vec3::ZERO
        }
    });
    let out = r.render(&t, &[&screen_left, &screen_right]);
    let (image_left, image_right) = cheeks(&r, &st);
    let l = |img: &LinearImage, p: (f32, f32)| luminance(img, p.0, p.1, 3);
    assert!(
        l(&out[0], image_right) > 1.3 * l(&out[1], image_right),
        "screen-left light brightens the subject's left cheek"
    );
    assert!(
        l(&out[0], image_left) < 0.77 * l(&out[1], image_left),
        "and leaves the other cheek darker"
    );
    assert!(l(&out[0], image_right) > 1.3 * l(&out[0], image_left));
}

#[test]
fn the_dome_lights_from_the_side_what_the_screen_lights_from_the_front() {
    let st = State::default();
    let desk = renderer(256, 256);
    let dome = Renderer::new(Scene {
        monitor: MonitorGeometry::dome(),
        ..Scene::new(Subject::default(), 256, 256)
    })
    .unwrap();
    let white = light(|_, _| Vec3::new(1.0, 1.0, 1.0));
    let left_edge = light(|_, c| {
        if c < COLS / 4 {
            Vec3::new(1.0, 1.0, 1.0)
        } else {
            Vec3::ZERO
        }
    });
    // Per renderer: the subject's left cheek (image right) over the right one
    // under the grid's left quarter, and the face's middle under white.
    let measure = |r: &Renderer| {
        let t = r.prepare(&Look::default(), &st);
        let out = r.render(&t, &[&left_edge, &white]);
        let (image_left, image_right) = cheeks(r, &st);
        let l = |img: &LinearImage, p: (f32, f32)| luminance(img, p.0, p.1, 3);
        let middle = ((image_left.0 + image_right.0) / 2.0, image_left.1);
        (
            l(&out[0], image_right) / l(&out[0], image_left),
            l(&out[1], middle),
        )
    };
    let ((desk_side, desk_front), (dome_side, dome_front)) = (measure(&desk), measure(&dome));
    assert!(
        dome_side > 1.5 * desk_side && dome_side > 3.0,
        "a light from 45-90 degrees to the side lights one cheek far more than the screen's edge: \
         {dome_side} on the dome, {desk_side} on the desk"
    );
    // The exposure is set so that white on either lights a frontal patch
    // alike; the nose's middle sees less of the dome, whose light comes from
    // round the face and is partly shadowed by it (0.71 times the desk's).
    assert!(
        (0.6..1.2).contains(&(dome_front / desk_front)),
        "{dome_front} against {desk_front}"
    );
}

#[test]
fn the_nose_casts_a_shadow() {
    // Only the outermost columns of the screen's right edge (image left) are lit.
    let lit_from_side = light(|_, c| {
        if c >= COLS - 4 {
            Vec3::new(1.0, 1.0, 1.0)
        } else {
            Vec3::ZERO
        }
    });
    let run = |shadows: bool| {
        let mut scene = Scene::new(Subject::default(), 256, 256);
        scene.shadows = shadows;
        let r = Renderer::new(scene).unwrap();
        let t = r.prepare(&Look::default(), &State::default());
        let lit = r.render(&t, &[&lit_from_side]).remove(0);
        let amb = r.ambient(&t);
        // The monitor's share of the light, without the room's.
        let monitor: Vec<f32> = lit
            .rgb
            .iter()
            .zip(&amb.rgb)
            .map(|(a, b)| a.y - b.y)
            .collect();
        (monitor, keypoints(&r, &State::default()))
    };
    let (with, k) = run(true);
    let (without, _) = run(false);
    // The shadow falls on the nose's image-right side, between its tip and the cheek.
    let (x0, x1) = (
        k[30][0] as usize,
        (k[35][0] + 0.5 * (k[13][0] - k[35][0])) as usize,
    );
    let (y0, y1) = (k[28][1] as usize, k[33][1] as usize);
    let darkened = (y0..=y1)
        .flat_map(|y| (x0..=x1).map(move |x| y * 256 + x))
        .filter(|&i| without[i] > 1e-3 && with[i] < 0.85 * without[i])
        .count();
    // A large area light casts a soft shadow: a band where part of the screen is hidden.
    assert!(
        darkened >= 20,
        "only {darkened} pixels beside the nose are in its shadow"
    );
    // Elsewhere on the face, e.g. the far cheek, shadows change little.
    let far = (k[3][1] as usize) * 256 + k[3][0] as usize;
    assert!((with[far] - without[far]).abs() < 0.2 * without[far].max(1e-3));
}

#[test]
fn keypoints_follow_pose_and_expression() {
    let r = renderer(256, 256);
    let base = State::default();
    let k0 = keypoints(&r, &base);
    let with = |f: &dyn Fn(&mut State)| {
        let mut s = base;
        f(&mut s);
        keypoints(&r, &s)
    };
    let yawed = with(&|s| s.pose.yaw = 10f32.to_radians());
    assert!(
        yawed[30][0] > k0[30][0] + 5.0,
        "turning to image right moves the nose tip right"
    );
    let up = with(&|s| s.pose.pitch = 10f32.to_radians());
    assert!(
        up[30][1] < k0[30][1] - 3.0,
        "tilting up moves the nose tip up"
    );
    let shifted = with(&|s| s.pose.translation = Vec3::new(0.02, 0.0, 0.0));
    let dx: Vec<f32> = shifted.iter().zip(&k0).map(|(a, b)| a[0] - b[0]).collect();
    assert!(
        dx.iter().all(|d| *d > 3.0),
        "a translation moves every point the same way"
    );
    let open = with(&|s| s.expression.mouth_open = 1.0);
    let gap = |k: &[[f32; 2]]| k[66][1] - k[62][1];
    assert!(
        gap(&open) > gap(&k0) + 4.0,
        "an open mouth parts the inner lips"
    );
    let blink = with(&|s| s.expression.blink = 1.0);
    let lid = |k: &[[f32; 2]]| k[41][1] - k[37][1];
    assert!(lid(&blink) < 0.2 * lid(&k0), "a blink closes the lids");
    let mut absent = base;
    absent.pose.present = false;
    assert!(keypoints(&r, &absent).iter().all(|p| p[0].is_nan()));
}

#[test]
fn nothing_is_nan_or_inf_anywhere_in_range() {
    let r = renderer(64, 64);
    let mut rng = Rng::new(9);
    let mut lights = vec![
        CellLight::uniform(ROWS, COLS, Vec3::ZERO),
        CellLight::uniform(ROWS, COLS, Vec3::new(1.0, 1.0, 1.0)),
        CellLight::uniform(ROWS, COLS, Vec3::new(1.0, 0.0, 0.0)),
    ];
    let random: Vec<Vec3> = (0..ROWS * COLS)
        .map(|_| Vec3::new(rng.f32(), rng.f32(), rng.f32()))
        .collect();
    lights.push(light(|r, c| random[r * COLS + c]));
    let refs: Vec<&CellLight> = lights.iter().collect();
    let extremes = [-1.0f32, 0.0, 1.0];
    for &y in &extremes {
        for &p in &extremes {
            for &roll in &extremes {
                let st = State {
                    pose: Pose {
                        yaw: (30.0 * y).to_radians(),
                        pitch: (15.0 * p).to_radians(),
                        roll: (8.0 * roll).to_radians(),
                        translation: Vec3::new(0.04 * y, 0.03 * p, 0.08 * roll),
                        body: Vec3::ZERO,
                        present: true,
                    },
                    expression: Expression {
                        mouth_open: (y + 1.0) / 2.0,
                        smile: (p + 1.0) / 2.0,
                        blink: (roll + 1.0) / 2.0,
                    },
                };
                let t = r.prepare(&Look::random(1, "nan"), &st);
                for img in r.render(&t, &refs) {
                    assert!(img.is_finite(), "NaN or Inf at {st:?}");
                }
            }
        }
    }
}

fn luma(p: [u8; 3]) -> f32 {
    0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32
}

#[test]
fn written_captures_and_recordings_reload_as_rendered() {
    let dir = std::env::temp_dir().join(format!("deskstage-write-{}", std::process::id()));
    let spec = CaptureSpec {
        sessions: 1,
        seconds: 0.5,
        fps: 6.0,
        size: 48,
        ..CaptureSpec::default()
    };
    dataset::write_capture(&dir.join("cap"), &spec, 0).unwrap();
    let (shape, face) = read_npy::<u8>(&dir.join("cap/face.npy")).unwrap();
    assert_eq!(shape, vec![3, 48, 48, 3]);
    assert_eq!(face.len(), 3 * 48 * 48 * 3);
    let (kshape, kps) = read_npy::<f32>(&dir.join("cap/keypoints.npy")).unwrap();
    assert_eq!(kshape, vec![3, 68, 2]);
    let (_, times) = read_npy::<f64>(&dir.join("cap/timestamps.npy")).unwrap();
    assert_eq!(times, vec![0.0, 1.0 / 6.0, 2.0 / 6.0]);
    // Writing again gives the same bytes.
    dataset::write_capture(&dir.join("cap2"), &spec, 0).unwrap();
    assert_eq!(
        std::fs::read(dir.join("cap/face.npy")).unwrap(),
        std::fs::read(dir.join("cap2/face.npy")).unwrap()
    );
    assert!(kps.iter().all(|v| v.is_finite()));

    let mut rs = RecordingSpec::standard("cuts").unwrap();
    rs.frames = 4;
    rs.width = 96;
    rs.height = 72;
    let rec = Recording::new(rs).unwrap();
    rec.write(&dir.join("rec")).unwrap();
    let mut face_video = Y4mReader::open(&dir.join("rec/face.y4m")).unwrap();
    let mut monitor_video = Y4mReader::open(&dir.join("rec/monitor.y4m")).unwrap();
    let mut truth_video =
        Y4mReader::open(&dir.join(format!("rec/truth-{}.y4m", rec.targets[0].0))).unwrap();
    for i in 0..4 {
        let f = rec.frame(i, true);
        let face: RgbImage = face_video.next_frame().unwrap().unwrap();
        for p in 0..face.width * face.height {
            let (a, b) = (face.pixel(p % 96, p / 96), f.face.pixel(p % 96, p / 96));
            assert!(
                (luma(a) - luma(b)).abs() <= 2.5,
                "face frame {i}: 4:2:0 keeps luma"
            );
        }
        let m = monitor_video.next_frame().unwrap().unwrap();
        assert!(
            m.data
                .iter()
                .zip(&f.monitor.data)
                .all(|(a, b)| (*a as i32 - *b as i32).abs() <= 2)
        );
        let g = truth_video.next_frame().unwrap().unwrap();
        assert!(
            g.data
                .iter()
                .zip(&f.ground_truth[0].data)
                .all(|(a, b)| (*a as i32 - *b as i32).abs() <= 2)
        );
    }
    assert!(face_video.next_frame().unwrap().is_none());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `deskstage captures --content stage` at the desk: the screen shows a light
/// stage's lights (one bright area on a dark screen, held), not videos, and the
/// session's meta says so, so that a training run can tell the sessions apart.
#[test]
fn a_desk_session_can_show_a_light_stages_lights() {
    let dir = std::env::temp_dir().join(format!("deskstage-content-{}", std::process::id()));
    let videos = CaptureSpec {
        sessions: 1,
        seconds: 3.0,
        fps: 2.0,
        size: 32,
        ..CaptureSpec::default()
    };
    let lights = CaptureSpec {
        content: Some(Style::Stage),
        ..videos.clone()
    };
    assert_eq!(videos.style(), Style::Capture);
    assert_eq!(lights.style(), Style::Stage);
    dataset::write_capture(&dir.join("lights"), &lights, 0).unwrap();
    let (shape, monitor) = read_npy::<u8>(&dir.join("lights/monitor.npy")).unwrap();
    let frame_len = shape[1] * shape[2] * shape[3];
    let playlist = Playlist::random(lights.seed, "train-0-monitor", 3.0, Style::Stage);
    for (i, shown) in monitor.chunks_exact(frame_len).enumerate() {
        assert_eq!(shown, &playlist.frame(i as f64 / 2.0).data[..], "frame {i}");
    }
    let meta = std::fs::read_to_string(dir.join("lights/meta.json")).unwrap();
    assert!(meta.contains("\"content\": \"stage\""), "{meta}");
    assert!(
        Style::of_capture("videos")
            .unwrap_err()
            .contains("capture or stage")
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn recordings_relight_the_same_frames() {
    let mut rs = RecordingSpec::standard("slow").unwrap();
    rs.width = 64;
    rs.height = 48;
    let rec = Recording::new(rs).unwrap();
    let f = rec.frame(10, true);
    assert_eq!(f.ground_truth.len(), rec.targets.len());
    // Ground truth under the recording's own source light is the noiseless recorded frame.
    let r = rec.renderer();
    let src = CellLight::from_frame(&rec.monitor_frame(f.time), ROWS, COLS);
    let t = r.prepare(&Look::random(rec.spec.seed, "recording-look"), &f.state);
    let clean = Sensor::default().clean(&r.render(&t, &[&src])[0]);
    let noise: f64 = clean
        .data
        .iter()
        .zip(&f.face.data)
        .map(|(a, b)| (*a as f64 - *b as f64).abs())
        .sum::<f64>()
        / clean.data.len() as f64;
    assert!(
        noise > 0.3 && noise < 6.0,
        "the recorded frame is the clean one plus sensor noise ({noise:.2})"
    );
}
