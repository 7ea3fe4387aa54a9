//! A test recording through the element against its exact ground truth: the
//! error must be the one the model card reports for the shipped model.

use lsydrelight_testkit::{
    checkout, default_model,
    recording::{ensure_recording, score_recording},
};

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
    let dir = checkout().join("target/recordings/call-90");
    ensure_recording(&dir, "call", 90).unwrap();
    for target in ["studio", "sunset", "left-key"] {
        let s = score_recording(&dir, target, true, &[]).unwrap();
        let want = card["targets"][target]["rmse_region"].as_f64().unwrap();
        assert_eq!(s.frames, 90);
        assert!(
            (s.rmse_region - want).abs() <= 0.01 * want,
            "{target}: RMSE {:.4} in the face region, the model card says {want:.4}",
            s.rmse_region
        );
        // Relighting must do better than leaving the frame as it was.
        assert!(s.rmse_region < s.input_rmse_region, "{target}: {s:?}");
    }
}
