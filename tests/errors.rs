//! Bad input gets a clear element error naming the problem and the fix: a
//! missing, corrupt or mismatched model, a missing target, an execution
//! provider that cannot start. (A missing ONNX Runtime library has its own test
//! binary: one process loads one library.)

use gst::prelude::*;
use lsydrelight_testkit::{default_model, element::element, init};

/// Starts the element in a pipeline and returns the error message it posts.
fn start_error(configure: impl FnOnce(&gst::Element)) -> String {
    init();
    let pipeline = gst::Pipeline::new();
    let src = gst::ElementFactory::make("videotestsrc")
        .property("num-buffers", 2)
        .build()
        .unwrap();
    let e = element();
    configure(&e);
    let sink = gst::ElementFactory::make("fakesink").build().unwrap();
    pipeline.add_many([&src, &e, &sink]).unwrap();
    gst::Element::link_many([&src, &e, &sink]).unwrap();
    let result = pipeline.set_state(gst::State::Paused);
    let msg = pipeline
        .bus()
        .unwrap()
        .timed_pop_filtered(gst::ClockTime::from_seconds(10), &[gst::MessageType::Error])
        .map(|m| match m.view() {
            gst::MessageView::Error(e) => format!("{} | {:?}", e.error(), e.debug()),
            _ => unreachable!(),
        });
    pipeline.set_state(gst::State::Null).unwrap();
    assert!(result.is_err(), "the pipeline must not start");
    msg.expect("an error message on the bus")
}

#[test]
fn missing_model() {
    let m = start_error(|e| e.set_property("model-location", "/nonexistent/model"));
    assert!(
        m.contains("/nonexistent/model/model.json") && m.contains("does not exist"),
        "{m}"
    );
    assert!(
        m.contains("model-location"),
        "the message names the fix: {m}"
    );
}

#[test]
fn corrupt_model() {
    let dir = std::env::temp_dir().join(format!("lsyd-corrupt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for f in std::fs::read_dir(default_model()).unwrap() {
        let f = f.unwrap();
        std::fs::copy(f.path(), dir.join(f.file_name())).unwrap();
    }
    std::fs::write(dir.join("encoder.onnx"), [0u8; 64]).unwrap();
    let m = start_error(|e| e.set_property("model-location", dir.to_str().unwrap()));
    assert!(m.contains("encoder.onnx") && m.contains("re-export"), "{m}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn mismatched_model() {
    let dir = std::env::temp_dir().join(format!("lsyd-mismatch-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for f in std::fs::read_dir(default_model()).unwrap() {
        let f = f.unwrap();
        std::fs::copy(f.path(), dir.join(f.file_name())).unwrap();
    }
    let p = dir.join("model.json");
    let text = std::fs::read_to_string(&p)
        .unwrap()
        .replace("\"lsydrelight-model\"", "\"some-other-model\"");
    std::fs::write(&p, text).unwrap();
    let m = start_error(|e| e.set_property("model-location", dir.to_str().unwrap()));
    assert!(
        m.contains("does not match") && m.contains("CONTRACT.md"),
        "{m}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn missing_target() {
    let m = start_error(|e| e.set_property("target-location", "/nonexistent/light.png"));
    assert!(
        m.contains("/nonexistent/light.png") && m.contains("target-location"),
        "{m}"
    );
}

#[test]
fn cuda_that_cannot_start_is_an_error_not_a_fallback() {
    let m = start_error(|e| e.set_property_from_str("execution-provider", "cuda"));
    assert!(
        m.contains("CUDA") && m.contains("execution-provider=cpu"),
        "{m}"
    );
}

#[test]
fn frames_too_small_after_videoconvert_are_an_error_not_a_hang() {
    init();
    let pipeline = gst::parse::launch(
        "videotestsrc num-buffers=3 ! video/x-raw,width=8,height=8 ! videoconvert \
         ! lsydrelight ! fakesink",
    )
    .unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let msg = pipeline
        .bus()
        .unwrap()
        .timed_pop_filtered(
            gst::ClockTime::from_seconds(20),
            &[gst::MessageType::Error, gst::MessageType::Eos],
        )
        .expect("an error within 20 s, not a pipeline stuck in preroll");
    pipeline.set_state(gst::State::Null).unwrap();
    let gst::MessageView::Error(err) = msg.view() else {
        panic!("expected an error, got {msg:?}");
    };
    let text = format!("{} | {:?}", err.error(), err.debug());
    assert!(
        text.contains("8x8") && text.contains("at least 16x16"),
        "{text}"
    );
}
