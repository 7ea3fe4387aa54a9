//! A test recording through the element against its exact ground truth: the
//! error must be the one the model card reports for the shipped model, and the
//! harness that scores it must decode every image the same way.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use lsydrelight_testkit::{
    checkout, default_model,
    recording::{ensure_recording, score_recording, score_unrelit},
};

const TARGETS: [&str; 3] = ["studio", "sunset", "left-key"];

/// The first 90 frames of the `call` recording, rendered once for all the tests
/// (which run in parallel and would otherwise write the same files at once).
fn call_90() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = checkout().join("target/recordings/call-90");
        ensure_recording(&dir, "call", 90).unwrap();
        dir
    })
}

#[test]
fn recorded_call_matches_the_model_card() {
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(default_model().join("model.json")).unwrap())
            .unwrap();
    let card = &manifest["metrics"]["element"]["call_90"];
    assert!(
        card.is_object(),
        "models/default/model.json has no metrics.element.call_90; run the evaluate_element example with --record"
    );
    for target in TARGETS {
        let s = score_recording(call_90(), target, true, &[], false).unwrap();
        let want = card["targets"][target]["rmse_region"].as_f64().unwrap();
        assert_eq!(s.frames, 90);
        assert!(
            (s.rmse_region - want).abs() <= 0.01 * want,
            "{target}: RMSE {:.4} in the face region, the model card says {want:.4}",
            s.rmse_region
        );
        // The input's error does not depend on the element, only on how the
        // harness decodes: a card recorded with another decoder differs here.
        let card_input = card["targets"][target]["input_rmse_region"]
            .as_f64()
            .unwrap();
        assert!(
            (s.input_rmse_region - card_input).abs() < 1e-9,
            "{target}: the input's RMSE is {:.4}, the model card's {card_input:.4}: it was \
             scored another way; re-run the evaluate_element example with --record",
            s.input_rmse_region
        );
        // Relighting must do better than leaving the frame as it was.
        assert!(s.rmse_region < s.input_rmse_region, "{target}: {s:?}");
    }
}

/// The face video through the pipeline and decoding the element's output takes,
/// without the element, is scored exactly as the input is: the two paths decode
/// the same images to the same pixels.
#[test]
fn the_harness_decodes_output_input_and_truth_alike() {
    let face = call_90().join("face.y4m");
    let itself = score_unrelit(&face, &face).unwrap();
    assert_eq!(itself.frames, 90);
    assert_eq!(
        (
            itself.rmse_frame,
            itself.rmse_region,
            itself.input_rmse_region
        ),
        (0.0, 0.0, 0.0),
        "the face video scored against itself"
    );
    for target in TARGETS {
        let truth = call_90().join(format!("truth-{target}.y4m"));
        let s = score_unrelit(&face, &truth).unwrap();
        assert!(s.input_rmse_region > 0.0, "{target}: {s:?}");
        assert_eq!(
            s.rmse_region, s.input_rmse_region,
            "{target}: the unrelit video's RMSE through the output's path and the input's"
        );
    }
}

/// Issue 16: the camera's noise, which the relit truth has not, must not make
/// the relit face flicker more than the camera's own picture. The studio
/// target brightens most, so it would multiply the noise most. The element's
/// change error (frame-to-frame change against the truth's) must stay well
/// below the unrelit input's; without the denoising it is above it, which
/// shows the measure tells the two apart.
#[test]
fn the_relit_call_flickers_less_than_the_camera() {
    let denoised = score_recording(call_90(), "studio", true, &[], false).unwrap();
    let kept = score_recording(call_90(), "studio", true, &[("denoise", "false")], false).unwrap();
    assert!(
        denoised.change_rmse < 0.75 * denoised.input_change_rmse,
        "change error {:.3} with denoising, the input's {:.3}",
        denoised.change_rmse,
        denoised.input_change_rmse
    );
    assert!(
        kept.change_rmse > denoised.input_change_rmse,
        "without denoising the change error is {:.3}, the input's {:.3}: the noise is no \
         longer multiplied, and this test no longer shows what denoising buys",
        kept.change_rmse,
        denoised.input_change_rmse
    );
    // Denoising must not cost accuracy.
    assert!(
        denoised.rmse_region <= kept.rmse_region,
        "face-region RMSE {:.3} with denoising, {:.3} without",
        denoised.rmse_region,
        kept.rmse_region
    );
}

/// Issue 11: the shipped int8 variant (`models/default-int8`, `lsyd.variants`) loads in
/// the element and relights the call within one percent of RMSE over the fp32 model
/// run alike on this machine. Its convolutions were chosen to half a percent on the
/// validation set (`metrics.int8.validation.max_rise_percent`), and the element held
/// that (+0.24% to +0.26%) while it relit the head alone; since the change also runs down
/// the shoulders it reads +0.51% / +0.67% / +0.82% (studio, sunset, left key;
/// `evaluate_element --model models/default-int8`), on errors 9-21% smaller, which the two
/// networks' difference over the crop's lower edge, now pasted down the body, adds to.
#[test]
fn the_int8_variant_relights_the_call_within_one_percent_of_fp32() {
    let int8 = checkout().join("models/default-int8");
    for target in TARGETS {
        let fp32 = score_recording(call_90(), target, true, &[], false).unwrap();
        let q = score_recording(
            call_90(),
            target,
            true,
            &[("model-location", int8.to_str().unwrap())],
            false,
        )
        .unwrap();
        assert_eq!(q.frames, 90);
        assert!(
            q.rmse_region <= 1.01 * fp32.rmse_region,
            "{target}: RMSE {:.4} in the face region with int8, {:.4} with fp32",
            q.rmse_region,
            fp32.rmse_region
        );
    }
}
