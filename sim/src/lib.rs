//! # deskstage: a desk light stage, simulated
//!
//! A deterministic, physically based renderer of the capture set-up in
//! "Personalized Video Relighting With an At-Home Light Stage" (Choi,
//! Christman, Sengupta, ECCV 2024): one person at a desk, lit by the monitor
//! in front of them and by room light, filmed by a webcam on the monitor.
//!
//! Light transport is linear in the monitor's radiance, so for any pose the
//! person's exact appearance under any other monitor content is known. That
//! exact ground truth is what the relighting network trains on, what the
//! GStreamer element is tested against and what the benchmarks score.
//!
//! - [`subject`], [`mesh`], [`material`]: the person, posed and dressed.
//! - [`monitor`], [`content`]: the screen as a grid of area lights and what it shows.
//! - [`render`]: per-pose light transport ([`render::Transport`]) and the webcam ([`render::Sensor`]).
//! - [`motion`]: pose, expression and presence over time.
//! - [`dataset`]: training captures, the held-out set and test recordings, on disk.
//! - [`webcam`]: a live webcam filming the person lit by given screen frames.

pub mod content;
pub mod dataset;
pub mod io;
pub mod material;
pub mod math;
pub mod mesh;
pub mod monitor;
pub mod motion;
pub mod noise;
pub mod raster;
pub mod render;
pub mod rng;
pub mod sheet;
pub mod subject;
pub mod webcam;
