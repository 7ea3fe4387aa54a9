//! The capture folder (`CAPTURE-LAYOUT.md`, version 1): `capture.json` lists
//! the sessions and the held-out one; each session is a folder. A session is
//! recorded into a hidden `.session-NNN.PID.part` folder and renamed into place
//! when complete; only then does `capture.json` name it.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::exit::Failure;

pub const FORMAT: &str = "lsydrelight-capture";
pub const SESSION_FORMAT: &str = "lsydrelight-capture-session";
pub const VERSION: u32 = 1;

/// `capture.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Index {
    pub format: String,
    pub version: u32,
    pub sessions: Vec<String>,
    pub held_out: Option<String>,
}

impl Default for Index {
    fn default() -> Self {
        Index {
            format: FORMAT.into(),
            version: VERSION,
            sessions: Vec::new(),
            held_out: None,
        }
    }
}

/// `session.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Session {
    pub format: &'static str,
    pub version: u32,
    pub started: String,
    pub seconds: f64,
    pub camera: String,
    pub screen: String,
    pub camera_frames: u64,
    pub light_frames: u64,
    pub screen_kept: bool,
    pub guidance: serde_json::Value,
}

/// The capture folder `--out` names, checked and read.
pub struct Capture {
    pub dir: PathBuf,
    pub index: Index,
}

impl Capture {
    /// Opens `dir`, creating it (and `capture.json`) if it does not exist.
    pub fn open(dir: &Path) -> Result<Capture, Failure> {
        if dir.exists() && !dir.is_dir() {
            return Err(Failure::new(format!(
                "--out {}: a file, not a folder; name a capture folder (new or from an earlier \
                 capture)",
                dir.display()
            )));
        }
        let file = dir.join("capture.json");
        let index = if file.is_file() {
            read_index(&file)?
        } else {
            if dir.is_dir() && std::fs::read_dir(dir).is_ok_and(|mut d| d.next().is_some()) {
                return Err(Failure::new(format!(
                    "--out {}: a folder with files but no capture.json; name a new folder or one \
                     an earlier capture wrote",
                    dir.display()
                )));
            }
            Index::default()
        };
        Ok(Capture {
            dir: dir.to_path_buf(),
            index,
        })
    }

    /// The next session's name: one past the highest listed or present, so a
    /// folder left by an aborted run is never reused.
    pub fn next_session(&self) -> String {
        let taken = |name: &str| -> Option<usize> {
            name.trim_start_matches('.')
                .strip_prefix("session-")
                .and_then(|s| s.split('.').next())
                .and_then(|n| n.parse().ok())
        };
        let present = std::fs::read_dir(&self.dir)
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|e| taken(&e.file_name().to_string_lossy()));
        let listed = self.index.sessions.iter().filter_map(|s| taken(s));
        let next = present.chain(listed).max().map_or(0, |n| n + 1);
        format!("session-{next:03}")
    }

    /// Adds a finished session to `capture.json` (written whole to a temporary
    /// file, then renamed, so it is never half written).
    pub fn add_session(&mut self, name: &str, held_out: bool) -> Result<(), Failure> {
        self.index.sessions.push(name.to_string());
        if held_out {
            self.index.held_out = Some(name.to_string());
        }
        write_json(&self.dir.join("capture.json"), &self.index)
    }
}

fn read_index(file: &Path) -> Result<Index, Failure> {
    let text = std::fs::read_to_string(file)
        .map_err(|e| Failure::new(format!("cannot read {}: {e}", file.display())))?;
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
        Failure::new(format!(
            "{}: not valid JSON ({e}); it is not a capture folder's index",
            file.display()
        ))
    })?;
    let format = value.get("format").and_then(|v| v.as_str());
    let version = value.get("version").and_then(|v| v.as_u64());
    if format != Some(FORMAT) || version != Some(VERSION as u64) {
        return Err(Failure::new(format!(
            "{}: format {} version {}, but this lsydrelight writes {FORMAT} version {VERSION}; \
             record into a new folder, or use the lsydrelight that wrote this one",
            file.display(),
            format.map_or("(none)".into(), |f| format!("\"{f}\"")),
            version.map_or("(none)".into(), |v| v.to_string()),
        )));
    }
    serde_json::from_value(value)
        .map_err(|e| Failure::new(format!("{}: not a capture index: {e}", file.display())))
}

pub fn write_json(path: &Path, value: &impl Serialize) -> Result<(), Failure> {
    let text = serde_json::to_string_pretty(value).expect("plain data serialises") + "\n";
    let temp = path.with_file_name(format!(
        ".{}.{}.part",
        path.file_name().unwrap_or_default().to_string_lossy(),
        std::process::id()
    ));
    std::fs::write(&temp, text)
        .and_then(|_| std::fs::rename(&temp, path))
        .map_err(|e| {
            let _ = std::fs::remove_file(&temp);
            Failure::new(format!("cannot write {}: {e}", path.display()))
        })
}

/// Now in RFC 3339, UTC, to the second.
pub fn now_rfc3339() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days as i64);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// The proleptic Gregorian date of a count of days since 1970-01-01 (Howard
/// Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sessions_are_numbered_past_every_listed_or_left_folder() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Capture::open(dir.path()).unwrap();
        assert_eq!(c.next_session(), "session-000");
        std::fs::create_dir(dir.path().join("session-000")).unwrap();
        c.add_session("session-000", false).unwrap();
        std::fs::create_dir(dir.path().join(".session-001.999.part")).unwrap();
        assert_eq!(c.next_session(), "session-002");
        c.add_session("session-002", true).unwrap();
        let again = Capture::open(dir.path()).unwrap();
        assert_eq!(again.index.sessions, ["session-000", "session-002"]);
        assert_eq!(again.index.held_out.as_deref(), Some("session-002"));
    }

    #[test]
    fn an_unknown_version_a_file_and_a_foreign_folder_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("capture.json"),
            r#"{"format": "lsydrelight-capture", "version": 7, "sessions": [], "held_out": null}"#,
        )
        .unwrap();
        let e = Capture::open(dir.path()).err().unwrap().to_string();
        assert!(e.contains("capture.json") && e.contains("version 7"), "{e}");
        let file = dir.path().join("capture.json");
        let e = Capture::open(&file).err().unwrap().to_string();
        assert!(e.contains("a file, not a folder"), "{e}");
        let foreign = tempfile::tempdir().unwrap();
        std::fs::write(foreign.path().join("notes.txt"), "x").unwrap();
        assert!(Capture::open(foreign.path()).is_err());
    }

    #[test]
    fn dates_are_rfc3339() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(20_454), (2026, 1, 1));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        let now = now_rfc3339();
        assert_eq!(now.len(), 20, "{now}");
        assert!(now.ends_with('Z'));
    }
}
