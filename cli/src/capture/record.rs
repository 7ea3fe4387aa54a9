//! What the capture's two app sinks do with each frame. A screen frame becomes
//! its monitor light (the plugin's own light code) in `light.npy` and its time
//! in `light-times.npy`; a camera frame goes to the face detector, and both
//! feed the guidance. Screen content itself is never kept here.

use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard};

use deskstage::io::GrowingNpyWriter;
use gst::prelude::*;
use gstlsydrelight::face::FaceDetector;
use gstlsydrelight::frame::Frame;
use gstlsydrelight::light::{LIGHT_COLS, LIGHT_ROWS, Light};
use gstlsydrelight::lsydrelight::frame_view;

use super::guidance::{self, Face, Guidance};
use crate::exit::Failure;

/// What the sinks have recorded so far.
pub struct Recorder {
    light: Option<GrowingNpyWriter<f32>>,
    light_times: Option<GrowingNpyWriter<f64>>,
    pub guidance: Guidance,
    pub camera_frames: u64,
    /// Running time of the latest camera and screen frames, seconds.
    pub camera_time: Option<f64>,
    pub screen_time: Option<f64>,
    /// The first failure in a sink, which the pipeline's own error follows.
    pub failure: Option<Failure>,
}

pub type Shared = Arc<Mutex<Recorder>>;

pub fn lock(shared: &Shared) -> MutexGuard<'_, Recorder> {
    // A panic in a sink leaves counts that are still right.
    shared.lock().unwrap_or_else(|e| e.into_inner())
}

impl Recorder {
    pub fn create(session: &Path) -> Result<Shared, Failure> {
        let open = |name: &str, e: std::io::Error| {
            Failure::new(format!(
                "cannot write {}: {e}",
                session.join(name).display()
            ))
        };
        let light =
            GrowingNpyWriter::create(&session.join("light.npy"), &[3, LIGHT_ROWS, LIGHT_COLS])
                .map_err(|e| open("light.npy", e))?;
        let times = GrowingNpyWriter::create(&session.join("light-times.npy"), &[])
            .map_err(|e| open("light-times.npy", e))?;
        Ok(Arc::new(Mutex::new(Recorder {
            light: Some(light),
            light_times: Some(times),
            guidance: Guidance::new(),
            camera_frames: 0,
            camera_time: None,
            screen_time: None,
            failure: None,
        })))
    }

    pub fn light_frames(&self) -> u64 {
        self.light_times.as_ref().map_or(0, |w| w.rows() as u64)
    }

    /// Finishes the arrays' headers; returns the number of screen frames.
    pub fn finish(&mut self, session: &Path) -> Result<u64, Failure> {
        let frames = self.light_frames();
        self.guidance.finish();
        let done = |name: &str, r: std::io::Result<()>| {
            r.map_err(|e| {
                Failure::new(format!(
                    "cannot write {}: {e}",
                    session.join(name).display()
                ))
            })
        };
        if let Some(w) = self.light.take() {
            done("light.npy", w.finish())?;
        }
        if let Some(w) = self.light_times.take() {
            done("light-times.npy", w.finish())?;
        }
        Ok(frames)
    }

    fn screen_frame(&mut self, t: f64, light: &Light) -> Result<(), Failure> {
        let (Some(lw), Some(tw)) = (self.light.as_mut(), self.light_times.as_mut()) else {
            return Ok(());
        };
        let io = |e: std::io::Error| Failure::new(format!("cannot write the light arrays: {e}"));
        lw.append(&light.0).map_err(io)?;
        tw.append(&[t]).map_err(io)?;
        self.screen_time = Some(t);
        self.guidance.screen(t, &light.0);
        Ok(())
    }

    fn camera_frame(&mut self, t: f64, face: Option<Face>) {
        self.camera_frames += 1;
        self.camera_time = Some(t);
        self.guidance.camera(t, face);
    }
}

/// A sample's running time in seconds, and the frame mapped for reading.
fn frame_of(sample: &gst::Sample) -> Option<(f64, gst_video::VideoFrameRef<&gst::BufferRef>)> {
    let buffer = sample.buffer()?;
    let info = gst_video::VideoInfo::from_caps(sample.caps()?).ok()?;
    let t = sample
        .segment()
        .and_then(|s| s.downcast_ref::<gst::ClockTime>())
        .and_then(|s| s.to_running_time(buffer.pts()))?;
    let frame = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer, &info).ok()?;
    Some((t.nseconds() as f64 / 1e9, frame))
}

/// Records on failure and stops the stream: the sink posts an error after it.
fn fail(shared: &Shared, failure: Failure) -> gst::FlowError {
    lock(shared).failure.get_or_insert(failure);
    gst::FlowError::Error
}

/// Calls `handle` with each frame of the app sink `name` and its running time in
/// seconds; `source` names the branch ("screen", "camera") in the error for a
/// frame that cannot be read.
fn on_frames(
    pipeline: &gst::Pipeline,
    name: &str,
    source: &'static str,
    shared: &Shared,
    mut handle: impl FnMut(f64, Frame<'_>) -> Result<(), gst::FlowError> + Send + 'static,
) {
    let sink = app_sink(pipeline, name);
    let shared = shared.clone();
    sink.set_callbacks(
        gst_app::AppSinkCallbacks::builder()
            .new_sample(move |sink| {
                let sample = sink.pull_sample().map_err(|_| gst::FlowError::Eos)?;
                let Some((t, frame)) = frame_of(&sample) else {
                    return Err(fail(
                        &shared,
                        Failure::new(format!(
                            "a {source} frame without a timestamp or readable caps; the {source} \
                             source must timestamp its frames (live sources do)"
                        )),
                    ));
                };
                let view = frame_view(&frame).ok_or(gst::FlowError::NotNegotiated)?;
                handle(t, view)?;
                Ok(gst::FlowSuccess::Ok)
            })
            .build(),
    );
}

/// Feeds `light-sink`'s frames to the recorder.
pub fn attach_light(pipeline: &gst::Pipeline, shared: &Shared) {
    let recorder = shared.clone();
    on_frames(pipeline, "light-sink", "screen", shared, move |t, view| {
        lock(&recorder)
            .screen_frame(t, &Light::from_frame(&view))
            .map_err(|f| fail(&recorder, f))
    });
}

/// Feeds `face-sink`'s frames, with the face `detector` finds, to the recorder.
pub fn attach_face(pipeline: &gst::Pipeline, shared: &Shared, mut detector: FaceDetector) {
    let recorder = shared.clone();
    on_frames(pipeline, "face-sink", "camera", shared, move |t, view| {
        let faces = detector.detect(&view).map_err(|e| {
            fail(
                &recorder,
                Failure::new(format!("the face detector failed: {e}")),
            )
        })?;
        let face = faces.first().map(|f| Face {
            width: f.width,
            height: f.height,
            eyes: [f.keypoints[0], f.keypoints[1]],
            nose: f.keypoints[2],
            mouth: f.keypoints[3],
            luminance: guidance::face_luminance(
                view.planes[0].data,
                view.planes[0].stride,
                view.width,
                view.height,
                [f.cx, f.cy],
                [f.width, f.height],
            ),
        });
        lock(&recorder).camera_frame(t, face);
        Ok(())
    });
}

fn app_sink(pipeline: &gst::Pipeline, name: &str) -> gst_app::AppSink {
    pipeline
        .by_name(name)
        .and_then(|e| e.downcast::<gst_app::AppSink>().ok())
        .expect("the description names this app sink")
}
