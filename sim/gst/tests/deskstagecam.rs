//! deskstagecam in a harness: the camera video it outputs is lit by the
//! screen frames it is given, at its own size, at most `fps` frames a second.

use gst::prelude::*;

fn init() {
    gst::init().unwrap();
    gstdeskstage::plugin_register_static().unwrap();
}

/// A screen frame of one colour, BGRx 64x36, at `ms` milliseconds.
fn screen_frame(value: u8, ms: u64) -> gst::Buffer {
    let mut buffer = gst::Buffer::from_mut_slice(vec![value; 64 * 36 * 4]);
    let b = buffer.get_mut().unwrap();
    b.set_pts(gst::ClockTime::from_mseconds(ms));
    b.set_duration(gst::ClockTime::from_mseconds(25));
    buffer
}

fn mean(buffer: &gst::Buffer) -> f64 {
    let map = buffer.map_readable().unwrap();
    map.iter().map(|&v| v as f64).sum::<f64>() / map.len() as f64
}

#[test]
fn the_person_is_lit_by_the_screen_and_filmed_at_the_camera_rate() {
    init();
    let mut h = gst_check::Harness::new_parse("deskstagecam width=80 height=60 fps=10");
    h.set_src_caps_str("video/x-raw,format=BGRx,width=64,height=36,framerate=40/1");
    // 40 fps in, 10 fps out: every fourth screen frame is filmed.
    let mut out = Vec::new();
    for i in 0..8u64 {
        let value = if i < 4 { 255 } else { 0 };
        assert_eq!(
            h.push(screen_frame(value, i * 25)),
            Ok(gst::FlowSuccess::Ok)
        );
        while let Some(b) = h.try_pull() {
            out.push(b);
        }
    }
    assert_eq!(out.len(), 2, "frames at 0 and 100 ms");
    assert_eq!(out[1].pts(), Some(gst::ClockTime::from_mseconds(100)));
    let caps = h.sinkpad().unwrap().current_caps().unwrap();
    let s = caps.structure(0).unwrap();
    assert_eq!(s.get::<&str>("format").unwrap(), "RGB");
    assert_eq!(
        (
            s.get::<i32>("width").unwrap(),
            s.get::<i32>("height").unwrap()
        ),
        (80, 60)
    );
    assert_eq!(out[0].size(), 80 * 60 * 3);
    let (lit, dark) = (mean(&out[0]), mean(&out[1]));
    assert!(lit > dark + 10.0, "white screen {lit}, black screen {dark}");
}
