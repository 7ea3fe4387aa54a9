//! The target light the user chose with `target-location`. It is decoded on
//! the application's thread when the property is set, so a change while
//! playing never stalls a frame; the streaming thread only encodes it, when
//! its generation is newer than the one the stream has.

use std::path::Path;
use std::sync::Arc;

use crate::light::Light;

#[derive(Default)]
pub struct TargetSlot {
    decoded: Option<Arc<Light>>,
    /// Bumped whenever the decoded target changes.
    generation: u64,
    /// Between start and stop: a target that cannot be read keeps the previous one.
    streaming: bool,
}

/// What became of a new target location.
pub enum Update {
    Applied,
    /// Stopped: the error surfaces when the element starts.
    Deferred,
    /// Playing: the previous target stays, for this reason.
    KeptPrevious(String),
}

impl TargetSlot {
    /// Takes a newly decoded (or failed) target; the check of whether the element
    /// streams and the change happen under the caller's one lock.
    pub fn update(&mut self, decoded: Result<Light, String>) -> Update {
        match decoded {
            Ok(light) => {
                self.decoded = Some(Arc::new(light));
                self.generation += 1;
                Update::Applied
            }
            Err(e) if self.streaming => Update::KeptPrevious(e),
            Err(_) => {
                self.decoded = None;
                Update::Deferred
            }
        }
    }

    /// The target to start with, decoding `location` if nothing is decoded yet,
    /// and its generation.
    pub fn start(&mut self, location: &Path) -> Result<(Arc<Light>, u64), String> {
        if self.decoded.is_none() {
            self.decoded = Some(Arc::new(Light::from_png(location)?));
            self.generation += 1;
        }
        self.streaming = true;
        Ok((
            self.decoded.clone().expect("decoded above"),
            self.generation,
        ))
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
