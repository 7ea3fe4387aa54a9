//! The target light the user chose: a preset (`target-preset`), an environment
//! map seen through the monitor (`target-environment` with `target-fov`,
//! `target-yaw`, `target-pitch`, `target-exposure`), or a PNG of monitor content
//! (`target-location`), in that order of precedence. It is resolved on the
//! thread that sets the property, so a change while playing never stalls a
//! frame; the streaming thread only fades to it and encodes it, when its
//! generation is newer than the one the stream has.

use super::lock;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use gst::glib;
use gst::subclass::prelude::*;

use super::imp::{CAT, LsydRelight};
use crate::light::Light;
use crate::targets::{Panorama, Preset, View};

/// Which target the settings name.
#[derive(Clone, Debug, PartialEq)]
pub enum TargetSource {
    Preset(Preset),
    Environment(PathBuf, View),
    Image(PathBuf),
}

impl std::fmt::Display for TargetSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TargetSource::Preset(p) => write!(f, "preset {}", p.nick()),
            TargetSource::Environment(path, v) => write!(
                f,
                "environment map {} (fov {}, yaw {}, pitch {}, exposure {})",
                path.display(),
                v.fov,
                v.yaw,
                v.pitch,
                v.exposure
            ),
            TargetSource::Image(path) => write!(f, "{}", path.display()),
        }
    }
}

#[derive(Default)]
pub struct TargetSlot {
    decoded: Option<Arc<Light>>,
    /// Bumped whenever the decoded target changes.
    generation: u64,
    /// Between start and stop: a target that cannot be read keeps the previous one.
    streaming: bool,
    /// The last environment map read, so a new yaw only projects it again.
    panorama: Option<(PathBuf, Arc<Panorama>)>,
}

/// What became of a new target.
pub enum Update {
    Applied,
    /// Stopped: the error surfaces when the element starts.
    Deferred,
    /// Playing: the previous target stays, for this reason.
    KeptPrevious(String),
}

impl TargetSlot {
    /// The environment map at `path`, read once and kept while the path stays.
    /// `slot` is locked only to look and to keep, never while a file is read.
    fn panorama(slot: &std::sync::Mutex<TargetSlot>, path: &Path) -> Result<Arc<Panorama>, String> {
        let cached = lock(slot)
            .panorama
            .as_ref()
            .filter(|(p, _)| p == path)
            .map(|(_, pano)| pano.clone());
        if let Some(pano) = cached {
            return Ok(pano);
        }
        let pano = Arc::new(Panorama::open(path)?);
        lock(slot).panorama = Some((path.to_owned(), pano.clone()));
        Ok(pano)
    }

    /// The light `source` names, reading files as needed (outside the lock).
    pub fn resolve(
        slot: &std::sync::Mutex<TargetSlot>,
        source: &TargetSource,
    ) -> Result<Light, String> {
        match source {
            TargetSource::Preset(p) => Ok(p.light()),
            TargetSource::Environment(path, view) => Ok(Self::panorama(slot, path)?.light(view)),
            TargetSource::Image(path) => Light::from_png(path),
        }
    }

    /// Takes a newly resolved (or failed) target; the check of whether the element
    /// streams and the change happen under the caller's one lock.
    pub fn update(&mut self, decoded: Result<Light, String>) -> Update {
        match decoded {
            Ok(light) => {
                if self.decoded.as_deref() != Some(&light) {
                    self.decoded = Some(Arc::new(light));
                    self.generation += 1;
                }
                Update::Applied
            }
            Err(e) if self.streaming => Update::KeptPrevious(e),
            Err(_) => {
                self.decoded = None;
                Update::Deferred
            }
        }
    }

    /// The target to start with, resolving `source` if nothing is resolved yet,
    /// and its generation.
    pub fn start(
        slot: &std::sync::Mutex<TargetSlot>,
        source: &TargetSource,
    ) -> Result<(Arc<Light>, u64), String> {
        if lock(slot).decoded.is_none() {
            let light = Self::resolve(slot, source)?;
            let mut s = lock(slot);
            s.decoded = Some(Arc::new(light));
            s.generation += 1;
        }
        let mut s = lock(slot);
        s.streaming = true;
        Ok((s.decoded.clone().expect("resolved above"), s.generation))
    }

    pub fn stop(&mut self) {
        self.streaming = false;
    }

    /// The target, if it is newer than `generation`.
    pub fn newer_than(&self, generation: u64) -> Option<(Arc<Light>, u64)> {
        (self.generation != generation)
            .then(|| self.decoded.clone().map(|l| (l, self.generation)))
            .flatten()
    }
}

impl LsydRelight {
    /// Sets a target property and resolves the target it names here, on the
    /// caller's thread (GstController's: the streaming thread).
    pub(super) fn set_target(&self, name: &str, value: &glib::Value) {
        let source = {
            let mut settings = lock(&self.settings);
            settings.set(name, value);
            settings.target_source()
        };
        let decoded = TargetSlot::resolve(&self.target, &source);
        let update = lock(&self.target).update(decoded);
        match update {
            Update::Applied => gst::debug!(CAT, imp = self, "{name}: target {source}"),
            Update::Deferred => gst::debug!(
                CAT,
                imp = self,
                "target {source} cannot be read; the error surfaces at start"
            ),
            Update::KeptPrevious(e) => gst::element_imp_warning!(
                self,
                gst::ResourceError::OpenRead,
                ("Keeping the previous target light: {}", e),
                [
                    "Set target-location to a readable PNG image of monitor content, target-environment to a readable panorama, or target-preset to a preset."
                ]
            ),
        }
    }
}
