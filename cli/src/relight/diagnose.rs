//! Pipeline errors as messages that name the file at fault, say what is wrong
//! with it and what to do. Which file is read from the name of the element
//! that posted the error (or of the bin holding it), as `graph` names them.

use std::path::Path;

use gst::prelude::*;

use super::graph::OWN_ERROR;
use super::job::Files;
use crate::exit::Failure;

enum Origin {
    Face,
    Screen,
    Target,
    Relight,
    Out,
    Predicted,
    Unknown,
}

fn origin(src: Option<&gst::Object>) -> Origin {
    let mut object = src.cloned();
    while let Some(o) = object {
        let name = o.name();
        for (prefix, origin) in [
            ("face-", Origin::Face),
            ("screen-", Origin::Screen),
            ("target-", Origin::Target),
            ("relight", Origin::Relight),
            ("out-", Origin::Out),
            ("predicted-", Origin::Predicted),
        ] {
            if name.starts_with(prefix) {
                return origin;
            }
        }
        object = o.parent();
    }
    Origin::Unknown
}

pub fn error(e: &gst::message::Error, files: &Files, missing_plugins: &[String]) -> Failure {
    let own = e.details().is_some_and(|d| d.name() == OWN_ERROR);
    let text = e.error().message().trim_end_matches('.').to_string();
    let input = |flag: &str, path: &Path| {
        let problem = if own {
            text.clone()
        } else {
            input_problem(e, missing_plugins)
        };
        Failure::new(format!("{flag} {}: {problem}", path.display()))
    };
    // The file sink fails for the disk; the encoder and muxer before it for the stream.
    let output = |path: &Path| {
        Failure::new(match e.error().kind::<gst::ResourceError>() {
            Some(_) => format!(
                "cannot write {}: {text}; check that its folder is writable and has room",
                path.display()
            ),
            None => format!("{}: {text}", path.display()),
        })
    };
    match origin(e.src()) {
        Origin::Face => input("--face", &files.face),
        Origin::Screen => input("--screen", files.screen.as_deref().unwrap_or(Path::new(""))),
        Origin::Target => input(
            "--target",
            files.target_video.as_deref().unwrap_or(Path::new("")),
        ),
        Origin::Relight => Failure::new(format!(
            "cannot relight: {}",
            element_text(e.error(), e.debug())
        )),
        Origin::Out => output(&files.out.path),
        Origin::Predicted => output(files.predicted.as_ref().map_or(Path::new(""), |p| &p.path)),
        Origin::Unknown => Failure::new(match e.debug() {
            Some(debug) => format!("{text} ({debug})"),
            None => text,
        }),
    }
}

/// What is wrong with an input GStreamer could not read, and what to do.
fn input_problem(e: &gst::message::Error, missing_plugins: &[String]) -> String {
    let error = e.error();
    if !missing_plugins.is_empty() {
        return format!(
            "GStreamer has no {} here; install the plugins that have it (on Debian: \
             gstreamer1.0-plugins-bad, gstreamer1.0-plugins-ugly, gstreamer1.0-libav) \
             or convert the recording, e.g. to H.264 in MP4",
            missing_plugins.join(", ")
        );
    }
    match error.kind::<gst::StreamError>() {
        // typefind's verdict: an unknown format, or a known one that is no recording ("This
        // appears to be a text file").
        Some(gst::StreamError::TypeNotFound | gst::StreamError::WrongType) => {
            return format!(
                "not a recording GStreamer can read ({}); pass a video file such as MP4 or MKV, \
                 or convert it",
                error.message().trim_end_matches('.')
            );
        }
        Some(gst::StreamError::Demux | gst::StreamError::Decode) => {
            return format!(
                "{}; the file may be damaged or cut short: check that it plays",
                error.message()
            );
        }
        _ => {}
    }
    if error.kind::<gst::ResourceError>().is_some() {
        return format!("cannot read it: {}", error.message());
    }
    error.message().to_string()
}

pub fn warning(w: &gst::message::Warning) -> String {
    match origin(w.src()) {
        Origin::Relight => element_text(w.error(), w.debug()),
        _ => w.error().message().to_string(),
    }
}

/// The element's own words: its detail says what to do, in terms of its
/// properties, which this tool sets from its options.
fn element_text(error: gst::glib::Error, debug: Option<gst::glib::GString>) -> String {
    let message = error.message().trim_end_matches('.').to_string();
    let text = match debug {
        // GStreamer puts where the error was posted on the first line: "file(line): function
        // (): /GstPipeline:pipeline0/...:"; the element's words follow.
        Some(d) => {
            let detail = d.split_once(":\n").map_or(d.as_str(), |(_, detail)| detail);
            format!("{message}: {detail}")
        }
        None => message,
    };
    text.replace("model-location", "--model")
        .replace("target-location", "--target")
        .replace("target-environment", "--target")
        .replace("target-preset", "--target")
}
