//! Reading and checking capture folders, as `lsydrelight capture` writes them
//! (the capture folder format, version 1): `capture.json`, and per session
//! `session.json`, `camera.mkv`, `light.npy` (M × 3 × 16 × 32 float32) and
//! `light-times.npy` (M float64). Everything is checked before any work
//! starts, so a bad folder fails at once with a message naming the file.

use std::path::{Path, PathBuf};

use deskstage::io::read_npy;
use gstlsydrelight::light::{LIGHT_COLS, LIGHT_LEN, LIGHT_ROWS};
use serde::Deserialize;

use crate::exit::Failure;

pub const CAPTURE_FORMAT: &str = "lsydrelight-capture";
pub const SESSION_FORMAT: &str = "lsydrelight-capture-session";
pub const VERSION: u32 = 1;

/// Share of the only session held out (its end) when no session is held out and there is one.
pub const HELD_OUT_SHARE: f64 = 0.2;

#[derive(Deserialize)]
struct CaptureJson {
    format: String,
    version: u32,
    sessions: Vec<String>,
    held_out: Option<String>,
}

#[derive(Deserialize)]
struct SessionJson {
    format: String,
    version: u32,
    #[serde(default)]
    started: String,
    camera_frames: Option<u64>,
}

/// One recorded session, its files checked.
#[derive(Debug)]
pub struct Session {
    /// `<capture folder name>/<session name>`, unique over all --capture folders.
    pub label: String,
    pub dir: PathBuf,
    pub started: String,
    /// Frames in camera.mkv, as the capture recorded them (for progress).
    pub camera_frames: Option<u64>,
    /// The screen's light grids, `LIGHT_LEN` values each, and their times in seconds.
    pub lights: Vec<f32>,
    pub light_times: Vec<f64>,
}

impl Session {
    pub fn camera(&self) -> PathBuf {
        self.dir.join("camera.mkv")
    }

    /// The index of the light on the face at `time`: the latest screen frame at or
    /// before `time - offset` (the screen's content reaches the face `offset` later).
    pub fn light_at(&self, time: f64, offset: f64) -> Option<usize> {
        let shown = time - offset;
        // Light times are sorted (checked on reading).
        self.light_times
            .partition_point(|&t| t <= shown)
            .checked_sub(1)
    }

    pub fn light(&self, index: usize) -> &[f32] {
        &self.lights[index * LIGHT_LEN..(index + 1) * LIGHT_LEN]
    }
}

/// Which part of the recordings is kept for evaluation.
#[derive(Debug, Clone, PartialEq)]
pub enum HeldOut {
    /// A whole session (its index in the list of sessions).
    Session(usize),
    /// The last [`HELD_OUT_SHARE`] (by time) of the only session.
    TailOfOnly,
}

/// Every session of every capture folder, and what is held out.
#[derive(Debug)]
pub struct Captures {
    pub sessions: Vec<Session>,
    pub held_out: HeldOut,
}

/// Reads and checks the capture folders given with --capture.
pub fn read(dirs: &[PathBuf]) -> Result<Captures, Failure> {
    let mut sessions = Vec::new();
    let mut marked = None;
    for dir in dirs {
        let index_path = dir.join("capture.json");
        if !dir.is_dir() {
            return Err(Failure::new(format!(
                "--capture {}: no such folder; pass a folder written by `lsydrelight capture`",
                dir.display()
            )));
        }
        let index: CaptureJson = read_json(&index_path, CAPTURE_FORMAT)?;
        if index.sessions.is_empty() {
            return Err(Failure::new(format!(
                "{}: lists no sessions; record one with `lsydrelight capture --out {}`",
                index_path.display(),
                dir.display()
            )));
        }
        if let Some(h) = &index.held_out
            && !index.sessions.contains(h)
        {
            return Err(Failure::new(format!(
                "{}: held_out names {h}, which is not one of its sessions",
                index_path.display()
            )));
        }
        for name in &index.sessions {
            if index.held_out.as_ref() == Some(name) {
                // The latest folder that marks a session wins, as the latest mark does within one.
                marked = Some(sessions.len());
            }
            sessions.push(read_session(dir, name)?);
        }
    }
    let held_out = match marked {
        Some(i) => HeldOut::Session(i),
        None if sessions.len() >= 2 => {
            // The most recent session: RFC 3339 UTC times order as strings.
            let latest = (0..sessions.len())
                .max_by(|&a, &b| sessions[a].started.cmp(&sessions[b].started))
                .unwrap_or(sessions.len() - 1);
            HeldOut::Session(latest)
        }
        None => HeldOut::TailOfOnly,
    };
    Ok(Captures { sessions, held_out })
}

fn read_json<T: for<'de> Deserialize<'de> + Versioned>(
    path: &Path,
    format: &str,
) -> Result<T, Failure> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        Failure::new(format!(
            "{}: {e}; is this a folder written by `lsydrelight capture`?",
            path.display()
        ))
    })?;
    let value: T = serde_json::from_str(&text).map_err(|e| {
        Failure::new(format!(
            "{}: not a {format} file ({e}); was it written by `lsydrelight capture`?",
            path.display()
        ))
    })?;
    let (found, version) = value.format_version();
    if found != format || version != VERSION {
        return Err(Failure::new(format!(
            "{}: format {found:?} version {version}; this lsydrelight reads {format:?} version \
             {VERSION} (re-record with this version's `lsydrelight capture`, or use the \
             lsydrelight that wrote it)",
            path.display()
        )));
    }
    Ok(value)
}

trait Versioned {
    fn format_version(&self) -> (&str, u32);
}

impl Versioned for CaptureJson {
    fn format_version(&self) -> (&str, u32) {
        (&self.format, self.version)
    }
}

impl Versioned for SessionJson {
    fn format_version(&self) -> (&str, u32) {
        (&self.format, self.version)
    }
}

fn read_session(capture: &Path, name: &str) -> Result<Session, Failure> {
    let dir = capture.join(name);
    let label = format!(
        "{}/{name}",
        capture
            .canonicalize()
            .ok()
            .as_deref()
            .and_then(Path::file_name)
            .unwrap_or_default()
            .to_string_lossy()
    );
    let meta: SessionJson = read_json(&dir.join("session.json"), SESSION_FORMAT)?;
    let camera = dir.join("camera.mkv");
    let camera_size = std::fs::metadata(&camera).map(|m| m.len()).unwrap_or(0);
    if camera_size == 0 {
        return Err(Failure::new(format!(
            "{}: missing or empty; the session has no camera recording (record it again)",
            camera.display()
        )));
    }
    let light_path = dir.join("light.npy");
    let times_path = dir.join("light-times.npy");
    let npy_error = |path: &Path, e: std::io::Error| {
        Failure::new(format!(
            "{}: {e}; the session's screen light is missing or damaged (record it again)",
            path.display()
        ))
    };
    let (shape, lights) = read_npy::<f32>(&light_path).map_err(|e| npy_error(&light_path, e))?;
    let (times_shape, light_times) =
        read_npy::<f64>(&times_path).map_err(|e| npy_error(&times_path, e))?;
    let m = shape.first().copied().unwrap_or(0);
    if shape != [m, 3, LIGHT_ROWS, LIGHT_COLS] || lights.len() != m * LIGHT_LEN {
        return Err(Failure::new(format!(
            "{}: shape {shape:?}, expected (M, 3, {LIGHT_ROWS}, {LIGHT_COLS}) float32",
            light_path.display()
        )));
    }
    if times_shape != [m] || light_times.len() != m {
        return Err(Failure::new(format!(
            "{}: shape {times_shape:?}, expected ({m},): one time per light in light.npy",
            times_path.display()
        )));
    }
    if m == 0 {
        return Err(Failure::new(format!(
            "{}: no screen frames were recorded in this session, so no frame has a known light; \
             record it again (or leave it out)",
            dir.display()
        )));
    }
    if light_times.windows(2).any(|w| w[1] < w[0]) || light_times.iter().any(|t| !t.is_finite()) {
        return Err(Failure::new(format!(
            "{}: the times are not finite and increasing",
            times_path.display()
        )));
    }
    if lights.iter().any(|v| !v.is_finite()) {
        return Err(Failure::new(format!(
            "{}: holds values that are not finite numbers",
            light_path.display()
        )));
    }
    Ok(Session {
        label,
        dir,
        started: meta.started,
        camera_frames: meta.camera_frames,
        lights,
        light_times,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn session(times: Vec<f64>) -> Session {
        Session {
            label: "c/s".into(),
            dir: PathBuf::new(),
            started: String::new(),
            camera_frames: None,
            lights: vec![0.0; times.len() * LIGHT_LEN],
            light_times: times,
        }
    }

    #[test]
    fn the_light_of_a_frame_is_the_latest_screen_frame_at_or_before_it() {
        let s = session(vec![0.0, 0.1, 0.2]);
        assert_eq!(s.light_at(0.1, 0.0), Some(1));
        assert_eq!(s.light_at(0.15, 0.0), Some(1));
        assert_eq!(s.light_at(5.0, 0.0), Some(2));
        // The screen's content reaches the face `offset` later.
        assert_eq!(s.light_at(0.15, 0.1), Some(0));
        assert_eq!(s.light_at(0.05, 0.1), None);
    }
}
