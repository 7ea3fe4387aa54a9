//! The engine without a pipeline: source-light averaging and feature smoothing
//! checked numerically on the shipped model, unknown-source mode, and the
//! model contract refusing models that do not match.

use std::path::Path;

use gstlsydrelight::engine::{
    self, ContractError, EngineError, FramePolicy, Provider, Relighter, Skips, Source, Temporal,
};
use gstlsydrelight::frame::FacePlace;
use gstlsydrelight::light::Light;
use gstlsydrelight::monitor_match::Features;
use gstlsydrelight::paths;
use lsydrelight_testkit::{
    checkout, default_model,
    person::{network_input, render_face},
};

fn relighter(temporal: Temporal) -> FramePolicy {
    relighter_of(&default_model(), temporal)
}

fn relighter_of(model: &Path, temporal: Temporal) -> FramePolicy {
    let env = engine::environment(&paths::default_ort_library())
        .expect("ONNX Runtime loads (run scripts/setup.sh)");
    let network = Relighter::new(env, model, 2, Provider::Cpu).expect("the shipped model loads");
    let mut r = FramePolicy::new(network, temporal, Skips::default());
    r.set_target(&Light::uniform([0.8, 0.6, 0.4])).unwrap();
    r
}

fn image(r: &FramePolicy, monitor: deskstage::math::Vec3) -> Vec<f32> {
    network_input(&render_face(monitor), r.relighter().resolution())
}

fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn source_light_is_the_papers_weighted_average() {
    let beta = 0.6;
    let mut r = relighter(Temporal {
        alpha: 1.0,
        beta,
        average_frames: 3,
        ..Temporal::default()
    });
    let img = image(&r, deskstage::math::Vec3::new(1.0, 1.0, 1.0));
    let lights = [0.9f32, 0.1, 0.5, 0.3].map(|v| Light::uniform([v, v * 0.5, v * 0.25]));
    let mut used = Vec::new();
    for l in &lights {
        used.push(
            r.relight(&img, FacePlace::default(), Source::Known(l.clone()), false)
                .unwrap()
                .source,
        );
    }
    // L_avg^t = Σ_{i<N} β^i L^{t−i} / Σ β^i, N = 3.
    let want = |t: usize| -> Vec<f32> {
        let (mut num, mut den) = (vec![0f32; lights[0].0.len()], 0f32);
        for i in 0..3.min(t + 1) {
            let w = beta.powi(i as i32);
            for (n, v) in num.iter_mut().zip(&lights[t - i].0) {
                *n += w * v;
            }
            den += w;
        }
        num.iter().map(|v| v / den).collect()
    };
    for (t, got) in used.iter().enumerate() {
        assert!(max_diff(&got.0, &want(t)) < 1e-6, "frame {t}");
    }
}

#[test]
fn features_are_smoothed_exponentially() {
    let alpha = 0.7;
    let light = Light::uniform([0.7, 0.7, 0.7]);
    let mut r = relighter(Temporal {
        alpha,
        beta: 0.6,
        average_frames: 1,
        ..Temporal::default()
    });
    let a = image(&r, deskstage::math::Vec3::new(1.0, 1.0, 1.0));
    let b = image(&r, deskstage::math::Vec3::new(0.3, 0.3, 0.6));
    let relight_lit = |r: &mut FramePolicy, img: &[f32]| {
        r.relight(
            img,
            FacePlace::default(),
            Source::Known(light.clone()),
            false,
        )
        .unwrap();
    };
    relight_lit(&mut r, &a);
    let fa = r.smoothed_features().unwrap().to_vec();
    r.reset();
    relight_lit(&mut r, &b);
    let fb = r.smoothed_features().unwrap().to_vec();
    r.reset();
    // f_t = α f_t + (1 − α) f_{t−1}: frame b after frame a.
    relight_lit(&mut r, &a);
    relight_lit(&mut r, &b);
    let fab = r.smoothed_features().unwrap();
    for (level, ((x, y), z)) in fa.iter().zip(&fb).zip(fab).enumerate() {
        let want: Vec<f32> = x
            .iter()
            .zip(y)
            .map(|(x, y)| alpha * y + (1.0 - alpha) * x)
            .collect();
        assert!(
            max_diff(z, &want) < 1e-5,
            "feature f{} off by {}",
            level + 1,
            max_diff(z, &want)
        );
    }
}

#[test]
fn constant_input_converges_to_the_single_frame_result() {
    let light = Light::uniform([0.6, 0.6, 0.6]);
    let mut fresh = relighter(Temporal::default());
    let img = image(&fresh, deskstage::math::Vec3::new(0.6, 0.6, 0.6));
    let single = fresh
        .relight(
            &img,
            FacePlace::default(),
            Source::Known(light.clone()),
            false,
        )
        .unwrap()
        .relit
        .unwrap();
    let mut r = relighter(Temporal::default());
    let other = image(&r, deskstage::math::Vec3::new(0.1, 0.1, 0.9));
    r.relight(
        &other,
        FacePlace::default(),
        Source::Known(Light::uniform([0.1, 0.1, 0.9])),
        false,
    )
    .unwrap();
    let mut last = Vec::new();
    for _ in 0..40 {
        last = r
            .relight(
                &img,
                FacePlace::default(),
                Source::Known(light.clone()),
                false,
            )
            .unwrap()
            .relit
            .unwrap();
    }
    assert!(
        max_diff(&last, &single) < 1e-4,
        "after 40 equal frames: {}",
        max_diff(&last, &single)
    );
}

#[test]
fn unknown_source_uses_the_predicted_light() {
    let mut r = relighter(Temporal {
        alpha: 1.0,
        beta: 0.6,
        average_frames: 1,
        ..Temporal::default()
    });
    let img = image(&r, deskstage::math::Vec3::new(1.0, 1.0, 1.0));
    let out = r
        .relight(&img, FacePlace::default(), Source::Unknown, false)
        .unwrap();
    let predicted = out.predicted.expect("unknown source predicts");
    assert_eq!(
        out.source, predicted,
        "the prediction stands in for the source light"
    );
    assert!(predicted.0.iter().all(|v| (0.0..=1.0).contains(v)));
    assert_eq!(r.counts().predictions, 1);
    // The next frame's prediction is smoothed with this one.
    let blue = image(&r, deskstage::math::Vec3::new(0.2, 0.2, 1.0));
    let next = r
        .relight(&blue, FacePlace::default(), Source::Unknown, false)
        .unwrap();
    let raw = next.predicted.expect("unknown source predicts");
    let w = Temporal::default().prediction_weight;
    let expected: Vec<f32> = predicted
        .0
        .iter()
        .zip(&raw.0)
        .map(|(p, n)| p + w * (n - p))
        .collect();
    assert!(max_diff(&next.source.0, &expected) < 1e-6);
    assert!(
        max_diff(&raw.0, &predicted.0) > 0.01,
        "the two frames' predictions differ"
    );
    let known = r
        .relight(
            &img,
            FacePlace::default(),
            Source::Known(Light::uniform([1.0; 3])),
            false,
        )
        .unwrap();
    assert!(
        known.predicted.is_none(),
        "a known source skips light prediction"
    );
}

#[test]
fn the_predicted_light_turns_the_colour_the_face_turns() {
    // The starter's light decoder hardly reads a screen's colour from a face it was
    // not trained on (this person's); following the face's own colour change, the
    // prediction turns blue under a blue screen and warm under a warm one.
    let starter = checkout().join("models/starter");
    let blueness = |light: &Light| Features::of(light).colour;
    let predicted_under = |tracking: bool| {
        let mut r = relighter_of(
            &starter,
            Temporal {
                colour_tracking: tracking,
                ..Temporal::default()
            },
        );
        let mut predict = |screen: deskstage::math::Vec3| {
            let img = image(&r, screen);
            let out = r
                .relight(&img, FacePlace::default(), Source::Unknown, false)
                .unwrap();
            blueness(&out.predicted.expect("unknown source predicts"))
        };
        for _ in 0..5 {
            predict(deskstage::math::Vec3::new(0.8, 0.8, 0.8));
        }
        let blue = predict(deskstage::math::Vec3::new(0.3, 0.4, 1.0));
        let warm = predict(deskstage::math::Vec3::new(1.0, 0.5, 0.2));
        (blue, warm)
    };
    let (blue, warm) = predicted_under(true);
    let (decoder_blue, decoder_warm) = predicted_under(false);
    println!(
        "blueness, blue then warm screen: tracked {blue:.3}, {warm:.3}; decoder alone {decoder_blue:.3}, {decoder_warm:.3}"
    );
    // The screens themselves: 0.41 and -0.47.
    let screens =
        blueness(&Light::uniform([0.3, 0.4, 1.0])) - blueness(&Light::uniform([1.0, 0.5, 0.2]));
    assert!(
        blue - warm > 2.0 * (decoder_blue - decoder_warm),
        "tracking follows the face no better than the decoder alone"
    );
    assert!(
        blue > 0.1 && warm < -0.1 && blue - warm > 0.5 * screens,
        "tracked: {blue:.3} under blue, {warm:.3} under warm (the screens differ by {screens:.3})"
    );
}

fn copy_model(to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(default_model()).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

fn load(dir: &Path) -> Result<Relighter, EngineError> {
    let env = engine::environment(&paths::default_ort_library()).unwrap();
    Relighter::new(env, dir, 1, Provider::Cpu)
}

fn edit_manifest(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let p = dir.join("model.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    edit(&mut m);
    std::fs::write(&p, serde_json::to_string(&m).unwrap()).unwrap();
}

#[test]
fn models_that_break_the_contract_are_refused_with_a_reason() {
    let base = std::env::temp_dir().join(format!("lsyd-contract-{}", std::process::id()));
    let case = |name: &str| -> std::path::PathBuf {
        let d = base.join(name);
        copy_model(&d);
        d
    };

    let missing = base.join("absent");
    match load(&missing) {
        Err(EngineError::Model(ContractError::Missing(p))) => assert!(p.ends_with("model.json")),
        other => panic!("missing model: {:?}", other.err()),
    }

    let d = case("version");
    edit_manifest(&d, |m| m["version"] = 3.into());
    let e = load(&d).err().expect("a newer contract version is refused");
    assert!(e.to_string().contains("version 2"), "{e}");

    let d = case("light-size");
    edit_manifest(&d, |m| m["light"]["rows"] = 8.into());
    assert!(
        load(&d)
            .err()
            .expect("a different light grid is refused")
            .to_string()
            .contains("8x32")
    );

    let d = case("shape");
    edit_manifest(&d, |m| {
        let shipped = m["resolution"].as_u64().expect("resolution is a number");
        m["resolution"] = (shipped + 32).into()
    });
    let e = load(&d)
        .err()
        .expect("shapes that disagree with the graphs are refused");
    assert!(
        matches!(e, EngineError::Model(ContractError::Mismatch(_))),
        "{e}"
    );

    let d = case("corrupt");
    std::fs::write(d.join("decoder.onnx"), b"not an onnx graph").unwrap();
    let e = load(&d).err().expect("a corrupt graph is refused");
    assert!(e.to_string().contains("decoder.onnx"), "{e}");

    let d = case("stage-missing");
    std::fs::remove_file(d.join("delight.onnx")).unwrap();
    assert!(load(&d).err().unwrap().to_string().contains("delight.onnx"));

    let d = case("not-json");
    std::fs::write(d.join("model.json"), "{").unwrap();
    assert!(
        load(&d)
            .err()
            .unwrap()
            .to_string()
            .contains("cannot be read")
    );

    std::fs::remove_dir_all(&base).unwrap();
}
