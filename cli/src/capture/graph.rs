//! The one capture pipeline: the screen branch ends in a tee named `screen`,
//! the camera branch in a tee named `camera`, so that either fragment may
//! refer to the other (a simulated camera films `screen.`). From the tees:
//! the camera to `camera.mkv` and to the face detector; the screen to the
//! monitor-light computation, and with `--keep-screen` to `screen.mkv`; with
//! `--playlist`, the videos also to a video sink for the user to watch.
//! Elements this module adds are named by what they serve (`out-camera-…`,
//! `light-…`), so errors can say which part failed.

use std::path::Path;

use gst::prelude::*;

use crate::exit::Failure;

/// What the pipeline is built from.
pub struct Fragments {
    pub camera: String,
    /// The screen fragment; with `--playlist`, a description of the playlist.
    pub screen: String,
    /// With `--playlist`: the files' decoding chains and where the user watches them.
    pub playlist: Option<Playlist>,
}

pub struct Playlist {
    pub files: Vec<std::path::PathBuf>,
    pub display: String,
}

/// Size the played videos are shown and measured at: a 16:9 screen, each video
/// letterboxed into it as a full-screen player shows it.
const PLAYLIST_SIZE: (u32, u32) = (1280, 720);

/// x264 for recordings to train on: constant quality, near lossless, no
/// B-frames or look-ahead (live sources must not wait on the encoder).
const ENCODER: &str =
    "x264enc speed-preset=veryfast tune=zerolatency pass=qual quantizer=16 key-int-max=60";

/// A path as a quoted gst-launch value.
fn quoted(path: &Path) -> String {
    let s = path.to_string_lossy();
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

impl Fragments {
    /// The gst-launch description of the whole pipeline writing into `session`.
    pub fn description(&self, session: &Path, keep_screen: bool) -> String {
        let mut d = Vec::new();
        match &self.playlist {
            None => d.push(format!(
                "{} ! videoconvert name=screen-convert ! tee name=screen",
                self.screen
            )),
            Some(p) => {
                let (w, h) = PLAYLIST_SIZE;
                d.push(format!(
                    "concat name=playlist ! videoconvert name=screen-convert ! videoscale \
                     name=screen-scale add-borders=true ! video/x-raw,width={w},height={h},\
                     pixel-aspect-ratio=1/1 ! tee name=screen"
                ));
                for (i, f) in p.files.iter().enumerate() {
                    d.push(format!(
                        "filesrc name=screen-file-{i} location={} ! decodebin name=screen-decode-{i} \
                         ! videoconvert name=screen-file-convert-{i} ! playlist.",
                        quoted(f)
                    ));
                }
                d.push(format!(
                    "screen. ! queue name=display-queue ! videoconvert name=display-convert ! {}",
                    p.display
                ));
            }
        }
        d.push(
            "screen. ! queue name=light-queue ! videoconvert name=light-convert ! \
             video/x-raw,format=RGB ! appsink name=light-sink sync=false"
                .into(),
        );
        if keep_screen {
            d.push(format!(
                "screen. ! queue name=out-screen-queue ! videoconvert name=out-screen-convert ! \
                 {ENCODER} name=out-screen-encode ! matroskamux name=out-screen-mux ! \
                 filesink name=out-screen-file sync=false location={}",
                quoted(&session.join("screen.mkv"))
            ));
        }
        d.push(format!("{} ! tee name=camera", self.camera));
        d.push(format!(
            "camera. ! queue name=out-camera-queue ! videoconvert name=out-camera-convert ! \
             {ENCODER} name=out-camera-encode ! matroskamux name=out-camera-mux ! \
             filesink name=out-camera-file sync=false location={}",
            quoted(&session.join("camera.mkv"))
        ));
        d.push(
            "camera. ! queue name=face-queue ! videoconvert name=face-convert ! \
             video/x-raw,format=RGB ! appsink name=face-sink sync=false"
                .into(),
        );
        d.join("  ")
    }
}

/// The pipeline, built with one `gst::parse::launch`.
pub fn build(
    fragments: &Fragments,
    session: &Path,
    keep_screen: bool,
) -> Result<gst::Pipeline, Failure> {
    let description = fragments.description(session, keep_screen);
    let element = gst::parse::launch(&description).map_err(|e| {
        Failure::new(format!(
            "the capture pipeline does not parse: {e}\n  --camera {}\n  --screen {}\n\
             Each is a gst-launch-1.0 fragment (e.g. --camera \"v4l2src device=/dev/video0\"); \
             the screen branch ends in a tee named `screen` and the camera's in one named \
             `camera`, which the other may use (`screen. ! queue ! deskstagecam`)",
            fragments.camera, fragments.screen
        ))
    })?;
    element
        .downcast::<gst::Pipeline>()
        .map_err(|_| Failure::new("internal error: the capture description is not a pipeline"))
}

/// Which part of the capture an element belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    Screen,
    Camera,
    Output,
    Other,
}

/// The part of the pipeline `src` (an element or pad, or something inside a
/// bin) belongs to: the outputs by name, the fragments by being upstream of
/// their tees (the screen's first: a simulated camera is upstream of both).
pub fn part_of(pipeline: &gst::Pipeline, src: Option<&gst::Object>) -> Part {
    let screen = upstream_of(pipeline, "screen");
    let camera = upstream_of(pipeline, "camera");
    let mut object = src.cloned();
    while let Some(o) = object {
        let name = o.name();
        if name.starts_with("out-") {
            return Part::Output;
        }
        if let Some(e) = o.downcast_ref::<gst::Element>() {
            if screen.contains(e) || name.starts_with("screen-") || name.starts_with("display-") {
                return Part::Screen;
            }
            if camera.contains(e) {
                return Part::Camera;
            }
        }
        object = o.parent();
    }
    Part::Other
}

/// Every element upstream of the element `name`, itself excluded.
fn upstream_of(pipeline: &gst::Pipeline, name: &str) -> Vec<gst::Element> {
    let mut found: Vec<gst::Element> = Vec::new();
    let mut todo: Vec<gst::Element> = pipeline.by_name(name).into_iter().collect();
    while let Some(e) = todo.pop() {
        for pad in e.sink_pads() {
            let Some(peer) = pad.peer() else { continue };
            // A ghost pad's parent is the bin; the element behind it is upstream too.
            if let Some(up) = peer.parent_element()
                && !found.contains(&up)
            {
                found.push(up.clone());
                todo.push(up);
            }
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_are_quoted_for_gst_launch() {
        assert_eq!(
            quoted(Path::new("/a b/\"c\".mkv")),
            "\"/a b/\\\"c\\\".mkv\""
        );
    }
}
