//! Numerical stability of the stateful engine, stressed: long runs, extreme
//! inputs, target equal to source, and determinism. (`cargo run --release
//! --example soak` runs the long version: 100,000 frames.)

use deskstage::math::Vec3;
use gstlsydrelight::engine::{self, FramePolicy, Provider, Relighter, Skips, Source, Temporal};
use gstlsydrelight::frame::FacePlace;
use gstlsydrelight::light::Light;
use gstlsydrelight::paths;
use lsydrelight_testkit::{
    default_model,
    person::{face_rgb, network_input, render_face},
};

fn relighter(threads: usize) -> FramePolicy {
    let env = engine::environment(&paths::default_ort_library())
        .expect("ONNX Runtime loads (run scripts/setup.sh)");
    let network = Relighter::new(env, &default_model(), threads, Provider::Cpu).unwrap();
    let mut r = FramePolicy::new(network, Temporal::default(), Skips::default());
    r.set_target(&Light::uniform([0.9, 0.7, 0.5])).unwrap();
    r
}

fn uniform_image(res: usize, rgb: [f32; 3]) -> Vec<f32> {
    rgb.iter()
        .flat_map(|&v| std::iter::repeat_n(v, res * res))
        .collect()
}

/// Resident memory of this process in MiB.
fn rss_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let kb: f64 = status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .unwrap()
        .parse()
        .unwrap();
    kb / 1024.0
}

fn assert_sane(relit: &[f32], what: &str) {
    assert!(relit.iter().all(|v| v.is_finite()), "{what}: NaN or Inf");
    assert!(
        relit.iter().all(|v| (0.0..=1.0).contains(v)),
        "{what}: outside [0, 1]"
    );
}

#[test]
fn long_runs_stay_finite_flat_and_without_drift() {
    let mut r = relighter(2);
    let res = r.relighter().resolution();
    let faces: Vec<Vec<f32>> = [
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(0.2, 0.3, 0.9),
        Vec3::new(0.9, 0.5, 0.1),
    ]
    .iter()
    .map(|&m| network_input(&render_face(m), res))
    .collect();
    let lights = [
        Light::uniform([1.0; 3]),
        Light::uniform([0.2, 0.3, 0.9]),
        Light::uniform([0.9, 0.5, 0.1]),
    ];
    let probe = |r: &mut FramePolicy| -> Vec<f32> {
        // A constant stretch: the smoothed state settles to the same fixed point every time.
        let mut out = Vec::new();
        for _ in 0..60 {
            out = r
                .relight(
                    &faces[0],
                    FacePlace::default(),
                    Source::Known(lights[0].clone()),
                    false,
                )
                .unwrap()
                .relit
                .unwrap();
        }
        out
    };
    let first = probe(&mut r);
    let mut memory = Vec::new();
    for block in 0..6 {
        for i in 0..500 {
            let k = (i * 7 + block) % 3;
            let out = r
                .relight(
                    &faces[k],
                    FacePlace::default(),
                    Source::Known(lights[(i / 3) % 3].clone()),
                    i % 50 == 0,
                )
                .unwrap();
            assert_sane(out.relit.as_ref().expect("finite"), "long run");
        }
        memory.push(rss_mb());
    }
    let last = probe(&mut r);
    let drift = first
        .iter()
        .zip(&last)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(
        drift < 1e-4,
        "the same input after 3,000 frames gives {drift} different output"
    );
    let growth = memory.last().unwrap() - memory[1];
    assert!(
        growth < 8.0,
        "memory grew {growth:.1} MiB over 2,500 frames: {memory:?}"
    );
}

#[test]
fn extreme_faces_and_flat_regions_stay_finite() {
    let mut r = relighter(2);
    let res = r.relighter().resolution();
    let mut noise = Vec::with_capacity(3 * res * res);
    let mut seed = 1u64;
    for _ in 0..3 * res * res {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        noise.push((seed >> 40) as f32 / (1u64 << 24) as f32);
    }
    let cases = [
        ("black", uniform_image(res, [0.0; 3])),
        ("white", uniform_image(res, [1.0; 3])),
        ("saturated red", uniform_image(res, [1.0, 0.0, 0.0])),
        (
            "uniform grey (zero-variance features)",
            uniform_image(res, [0.5; 3]),
        ),
        ("noise", noise),
    ];
    for (name, img) in &cases {
        for source in [
            Source::Known(Light::uniform([0.0; 3])),
            Source::Known(Light::uniform([1.0; 3])),
            Source::Unknown,
        ] {
            r.reset();
            let out = r.relight(img, FacePlace::default(), source, true).unwrap();
            assert_sane(out.relit.as_ref().expect("finite output"), name);
            assert!(out.predicted.unwrap().is_finite());
        }
    }
}

#[test]
fn strobing_monitor_stays_bounded() {
    let mut r = relighter(2);
    let face = network_input(face_rgb(), r.relighter().resolution());
    let (black, white) = (Light::uniform([0.0; 3]), Light::uniform([1.0; 3]));
    let mut previous: Option<Vec<f32>> = None;
    let mut biggest_step = 0.0f32;
    for i in 0..120 {
        let light = if i % 2 == 0 {
            black.clone()
        } else {
            white.clone()
        };
        let out = r
            .relight(&face, FacePlace::default(), Source::Known(light), false)
            .unwrap()
            .relit
            .unwrap();
        assert_sane(&out, "strobe");
        if let Some(p) = &previous
            && i > 10
        {
            let step =
                p.iter().zip(&out).map(|(a, b)| (a - b).abs()).sum::<f32>() / out.len() as f32;
            biggest_step = biggest_step.max(step);
        }
        previous = Some(out);
    }
    // Averaging and smoothing keep a frame-rate strobe from flickering the result
    // by more than a few levels of 255.
    assert!(
        biggest_step < 0.03,
        "mean frame-to-frame change {biggest_step} under a strobing monitor"
    );
}

#[test]
fn target_equal_to_source_changes_little() {
    let mut r = relighter(2);
    let res = r.relighter().resolution();
    let light = Light::uniform([0.8, 0.8, 0.8]);
    let face = network_input(&render_face(Vec3::new(0.8, 0.8, 0.8)), res);
    r.set_target(&light).unwrap();
    let same = r
        .relight(
            &face,
            FacePlace::default(),
            Source::Known(light.clone()),
            false,
        )
        .unwrap()
        .relit
        .unwrap();
    r.reset();
    r.set_target(&Light::uniform([0.1, 0.1, 0.6])).unwrap();
    let other = r
        .relight(&face, FacePlace::default(), Source::Known(light), false)
        .unwrap()
        .relit
        .unwrap();
    let mad = |a: &[f32], b: &[f32]| {
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f32>() / a.len() as f32
    };
    assert!(
        mad(&same, &face) < 0.25 * mad(&other, &face),
        "relighting to the same light changes the image {} vs {} for another light",
        mad(&same, &face),
        mad(&other, &face)
    );
}

#[test]
fn identical_input_gives_identical_output() {
    let run = |threads: usize| {
        let mut r = relighter(threads);
        let res = r.relighter().resolution();
        let faces = [
            network_input(face_rgb(), res),
            network_input(&render_face(Vec3::new(0.3, 0.3, 0.8)), res),
        ];
        (0..6)
            .map(|i| {
                r.relight(
                    &faces[i % 2],
                    FacePlace::default(),
                    Source::Known(Light::uniform([0.1 * i as f32; 3])),
                    true,
                )
                .unwrap()
                .relit
                .unwrap()
            })
            .collect::<Vec<_>>()
    };
    let a = run(2);
    assert_eq!(a, run(2), "same machine, same threads: bit-identical");
    let b = run(1);
    let worst = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "1 and 2 threads differ by {worst}");
}
