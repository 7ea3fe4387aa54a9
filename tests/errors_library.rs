//! A missing ONNX Runtime library is an element error naming the path and how
//! to install it. Its own test binary: a process loads ONNX Runtime once.

use gst::prelude::*;
use lsydrelight_testkit::init;

#[test]
fn missing_onnx_runtime_library() {
    init();
    let pipeline = gst::parse::launch(
        "videotestsrc num-buffers=2 ! lsydrelight ort-library=/nonexistent/libonnxruntime.so ! fakesink",
    )
    .unwrap();
    assert!(pipeline.set_state(gst::State::Paused).is_err());
    let m = pipeline
        .bus()
        .unwrap()
        .timed_pop_filtered(gst::ClockTime::from_seconds(10), &[gst::MessageType::Error])
        .expect("an error message");
    let gst::MessageView::Error(e) = m.view() else {
        unreachable!()
    };
    let text = format!("{} {:?}", e.error(), e.debug());
    pipeline.set_state(gst::State::Null).unwrap();
    assert!(text.contains("/nonexistent/libonnxruntime.so"), "{text}");
    assert!(
        text.contains("scripts/setup.sh") && text.contains("LSYDRELIGHT_ORT_LIBRARY"),
        "{text}"
    );
}
