//! Rehearsal sessions: the simulator's people under the dome the light code
//! stands for, mixed into a personal model's training.
//!
//! A desk's screen lights a face from within about 26 degrees of straight
//! ahead, so a person's own captures hold no light from the side; the starter
//! model learnt those from the simulator's dome (`deskstage captures --stage
//! dome`). Fine-tuning on the captures alone would let the network forget
//! them, so a few short dome sessions of people the starter trained on are
//! rendered into the training data beside the person's own, and training
//! pairs frames within them as within any session. The trainer knows them by
//! their folder's name (`rehearsal-`, `lsyd.data.REHEARSAL_PREFIX`) and draws
//! their pairs for a tenth of each batch however many they are
//! (`lsyd.personal.REHEARSAL_SHARE`): drawn as often as the person's own, they
//! made the model worse at the desk than the starter it began from.

use std::path::Path;

use deskstage::dataset::{self, CaptureSpec, Stage};

use crate::exit::Failure;

/// Simulated people rehearsed, from the starter's training people (100-131).
pub const PEOPLE: [u64; 4] = [100, 108, 116, 124];
/// Seconds of each rehearsal session (10 frames a second).
const SECONDS: f64 = 10.0;

/// Writes the rehearsal sessions not yet in `captures` (the trainer's
/// training sessions folder) as `rehearsal-dome-<person>`; returns how many
/// sessions are there.
pub fn write(captures: &Path) -> Result<usize, Failure> {
    for person in PEOPLE {
        let dir = captures.join(format!("rehearsal-dome-{person}"));
        if dir.join("face.npy").is_file() {
            continue;
        }
        let spec = CaptureSpec {
            subject_seed: person,
            seed: person + 2000,
            sessions: 1,
            seconds: SECONDS,
            stage: Stage::Dome,
            ..CaptureSpec::default()
        };
        // Written whole or not at all: a stopped run starts this session again.
        let partial = captures.join(format!(".rehearsal-dome-{person}"));
        let _ = std::fs::remove_dir_all(&partial);
        dataset::write_capture(&partial, &spec, 0)
            .and_then(|()| std::fs::rename(&partial, &dir))
            .map_err(|e| Failure::new(format!("cannot write {}: {e}", dir.display())))?;
    }
    Ok(PEOPLE.len())
}
