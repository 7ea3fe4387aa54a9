//! The camera's noise taken out of the frame's detail round the face, over
//! time, before the lighting change multiplies it.
//!
//! The lighting change is a smooth gain, so the frame keeps its own detail,
//! and with it the camera's noise: where the change brightens, the noise grows
//! with it, and it differs from frame to frame where the relit truth has none.
//! On the simulator's recordings that noise is nearly all of the element's
//! flicker (docs/flicker.md).
//!
//! Each plane is split into a smooth band (a box blur of [`SPLIT_RADIUS`]) and
//! its detail. The smooth band passes as it is, so a change of the screen's
//! light or a cut shows at once. The detail is filtered recursively, sample
//! by sample: where it differs from the filtered detail of the frame before by
//! about what noise makes it differ, only [`STILL_SHARE`] of the new frame's
//! detail is taken; where it differs by much more (the face moved, or turned),
//! the new detail is taken whole, so a moving face does not leave a trail.
//! The noise's level is learnt from the frames themselves, per band of
//! brightness, each frame filtered against what the frames before it taught:
//! a camera's noise changes over seconds, and so each frame is walked once.
//! The result shows over the disc round the face that the lighting change
//! covers, fading out where the change does, so the noise does not change
//! level at an edge.

use super::{Crop, FrameMut, PixelFormat};
use crate::parallel::beside;

use channel::ChannelState;
use disc::Disc;
use motion::{learn_noise, per_band};
use walk::{ChannelRows, Half, PlaneView, Scratch, Walk, walk_halves};

/// Radius, in plane pixels, of the box blur whose rest is the detail that is
/// filtered over time: 5 × 5 samples, which leave a fifth of the noise in
/// the smooth band. A wider split left moving texture in the detail, where it
/// lags (the moving-face test).
const SPLIT_RADIUS: usize = 2;
/// Radius of the local mean of the squared difference from the frame before
/// that tells motion from noise: 3 × 3 samples, so a single noisy sample does
/// not count as motion.
const MOTION_RADIUS: usize = 1;
/// Share of a new frame's detail taken where nothing moved: the filtered
/// detail then averages about the last twelve frames, its noise 0.28 of the
/// frame's.
pub const STILL_SHARE: f32 = 0.15;
/// Local mean squared difference, over the noise's, up to which a sample
/// counts as still ([`STILL_SHARE`]) and from which as moving (taken whole),
/// with a smooth step between. The mean of 9 squared noise differences
/// reaches 2 about once in 30 samples and 6 almost never; higher
/// thresholds held more noise back but left a trail behind texture moving
/// 2 pixels a frame (the moving-face test).
const STILL_RATIO: f32 = 2.0;
const MOVING_RATIO: f32 = 6.0;
/// Share of the lighting change's fade (`feather`) through which the
/// denoising still shows whole; it fades out over the rest. The truth has no
/// noise anywhere, and a change of noise level is a softer edge than one of
/// light.
const WHOLE_FADE: f32 = 0.5;
/// Least variance of the difference of detail between frames, in 8-bit
/// levels squared: about what rounding to whole levels makes alone.
const MIN_NOISE: f32 = 0.2;
/// How much the learnt noise level may rise from one frame to the next, as a
/// share of it (it falls at once): frames where nearly everything moves
/// overestimate the noise, which would then hide the motion. A camera's noise
/// changes with its exposure, over seconds.
const NOISE_RISE: f32 = 0.02;
/// About how many samples a frame the noise's level is learnt from.
const NOISE_SAMPLES: usize = 20_000;
/// Levels (of 256) in each band of the smooth value with its own noise level.
const LEVELS: usize = 32;
const BANDS: usize = 256 / LEVELS;

/// Samples of the areas of a frame's channels from which each area is walked
/// in two halves, on two threads. A sample takes about 3 ns; splitting saves
/// half the walk and costs handing the half to another thread (about 20 µs,
/// `paste_speed`'s last line; about 0.1 ms when each split started a thread), so it
/// pays from about 13,000 samples. Kept higher, where the gain is sure.
const SPLIT_FROM: usize = 65_536;

/// Which walk a pass over the frame's channels does.
#[derive(Clone, Copy, PartialEq)]
enum Phase {
    /// Teaches the noise's level to the channels that have none yet.
    Learn,
    /// Filters every channel shown (or keeps its detail, with no noise level).
    Denoise,
}

/// Temporal denoising of the detail round the face; one per stream.
pub struct DetailDenoiser {
    /// The stream the state is of: format and frame size.
    stream: Option<(PixelFormat, usize, usize)>,
    /// One per channel, in the order the format's passes walk them.
    channels: Vec<ChannelState>,
    scratch: Scratch,
    /// The scratch of the other thread, which walks the areas' bottom halves.
    second: Scratch,
    /// [`SPLIT_FROM`]; the tests split every area.
    split_from: usize,
    /// The build of the walk this CPU runs; the tests run each it can.
    build: Build,
}

/// A build of the walk, for the vector width the CPU has. Every build runs
/// the same IEEE operations in the same order, so all give the same bytes
/// (see `gain_field::gain_row`); a wider one does more samples at a time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Build {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// AVX-512 F, BW and VL: 16 floats a vector, twice AVX2's.
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Build {
    /// The builds this CPU can run, the widest last.
    fn available() -> Vec<Build> {
        let mut builds = vec![Build::Portable];
        builds.extend(Build::vector_builds());
        builds
    }

    /// The builds for this CPU's vector extensions.
    #[cfg(target_arch = "x86_64")]
    fn vector_builds() -> Vec<Build> {
        let avx2 = std::arch::is_x86_feature_detected!("avx2");
        [(avx2, Build::Avx2), (super::has_avx512(), Build::Avx512)]
            .into_iter()
            .filter_map(|(has, build)| has.then_some(build))
            .collect()
    }

    #[cfg(not(target_arch = "x86_64"))]
    fn vector_builds() -> Vec<Build> {
        Vec::new()
    }

    fn widest() -> Build {
        *Build::available()
            .last()
            .expect("the portable build is always there")
    }
}

impl Default for DetailDenoiser {
    fn default() -> DetailDenoiser {
        DetailDenoiser {
            stream: None,
            channels: Vec::new(),
            scratch: Scratch::default(),
            second: Scratch::default(),
            split_from: SPLIT_FROM,
            build: Build::widest(),
        }
    }
}

impl DetailDenoiser {
    /// Forgets the past: the next frame passes as it is and starts afresh.
    /// Returns whether there was a past to forget.
    pub fn reset(&mut self) -> bool {
        self.stream = None;
        !std::mem::take(&mut self.channels).is_empty()
    }

    /// Denoises `frame` round `crop`, as far as the lighting change of fade
    /// `feather` reaches round the head: whole through the change's inner circle and
    /// [`WHOLE_FADE`] of its fade, then fading out, at `strength` in [0, 1]
    /// (a face fading in or out).
    pub fn apply(&mut self, frame: &mut FrameMut, crop: Crop, feather: usize, strength: f32) {
        let stream = Some((frame.format, frame.width, frame.height));
        if self.stream != stream {
            self.reset();
            self.stream = stream;
        }
        let disc = Disc::new(crop, feather, strength);
        let passes = frame.format.passes();
        let planes: Vec<PlaneView> = (passes.iter())
            .flat_map(|pass| {
                let plane = PlaneView::of(frame, pass);
                pass.lanes.iter().flatten().map(move |_| plane)
            })
            .collect();
        self.channels
            .resize_with(planes.len(), ChannelState::default);
        for (channel, plane) in self.channels.iter_mut().zip(&planes) {
            let area = disc.area(plane.subsample, plane.size);
            if area[2] == 0 || area[3] == 0 || disc.strength <= 0.0 {
                // Nothing shown: the past no longer matches what is shown next.
                channel.detail.clear();
                channel.area = [0; 4];
            } else {
                channel.move_to(area);
            }
        }
        // In a stream's first frames no noise level is learnt yet: the frame
        // teaches it first, so that the first with a past is filtered.
        if (self.channels.iter()).any(|c| c.walks(Phase::Learn)) {
            self.walk_channels(frame, &disc, Phase::Learn);
        }
        self.walk_channels(frame, &disc, Phase::Denoise);
    }

    /// Walks the channels that `phase` walks, each area's top half on this
    /// thread and its bottom half on another (the whole area here, where
    /// the frame's areas are too small to split), then learns the noise's
    /// level from what each walk saw.
    fn walk_channels(&mut self, frame: &mut FrameMut, disc: &Disc, phase: Phase) {
        let walks: Vec<bool> = self.channels.iter().map(|c| c.walks(phase)).collect();
        let samples: usize = (self.channels.iter().zip(&walks))
            .filter(|(_, walks)| **walks)
            .map(|(c, _)| c.area[2] * c.area[3])
            .sum();
        let split = samples >= self.split_from;
        let passes = frame.format.passes();
        let views: Vec<PlaneView> = passes.iter().map(|p| PlaneView::of(frame, p)).collect();
        let mut planes = frame.planes.each_mut().map(Some);
        let mut channels = self.channels.iter_mut().zip(&walks);
        let [mut tops, mut bottoms] = [Vec::new(), Vec::new()];
        for (pass, plane) in passes.iter().zip(views) {
            let (data, _) = planes[pass.plane].take().expect("a plane a pass");
            let mut lanes = Vec::new();
            for (lane, _) in pass.lanes.iter().enumerate().filter(|(_, c)| c.is_some()) {
                let (channel, walks) = channels.next().expect("a channel a lane");
                if *walks {
                    lanes.push((lane, channel));
                }
            }
            let Some((_, first)) = lanes.first() else {
                continue;
            };
            // The plane's channels hold the same area.
            let [_, y0, _, h] = first.area;
            let mid = if split && h >= 2 { h / 2 } else { h };
            let walk = |c: &ChannelState| match phase {
                Phase::Learn => Walk::Learn,
                Phase::Denoise => match per_band(&c.noise) {
                    Some(noise) => Walk::Filter(noise.map(|n| 1.0 / n)),
                    None => Walk::Keep,
                },
            };
            let (mut top, mut bottom) = (Vec::new(), Vec::new());
            for (lane, channel) in lanes {
                if mid < h {
                    channel.copy_edges(data, &plane, lane, mid);
                }
                let walk = walk(channel);
                let ChannelState {
                    area,
                    detail,
                    seen,
                    edges,
                    ..
                } = channel;
                let (top_detail, bottom_detail) = detail.split_at_mut(mid * area[2]);
                let [top_seen, bottom_seen] = seen;
                let [top_edges, bottom_edges] = &*edges;
                top.push(ChannelRows {
                    lane,
                    area: *area,
                    rows: 0..mid,
                    detail: top_detail,
                    edges: top_edges,
                    seen: top_seen,
                    walk,
                });
                if mid < h {
                    bottom.push(ChannelRows {
                        lane,
                        area: *area,
                        rows: mid..h,
                        detail: bottom_detail,
                        edges: bottom_edges,
                        seen: bottom_seen,
                        walk,
                    });
                }
            }
            let at = ((y0 + mid) * plane.stride).min(data.len());
            let (top_data, bottom_data) = data.split_at_mut(at);
            tops.push(Half {
                data: top_data,
                data_row: 0,
                plane,
                channels: top,
            });
            if !bottom.is_empty() {
                bottoms.push(Half {
                    data: bottom_data,
                    data_row: y0 + mid,
                    plane,
                    channels: bottom,
                });
            }
        }
        let (scratch, second, build) = (&mut self.scratch, &mut self.second, self.build);
        if bottoms.is_empty() {
            walk_halves(tops, disc, scratch, build);
        } else {
            beside(
                || walk_halves(bottoms, disc, second, build),
                || walk_halves(tops, disc, scratch, build),
            );
        }
        for (channel, _) in (self.channels.iter_mut().zip(&walks)).filter(|(_, w)| **w) {
            let [top, bottom] = &mut channel.seen;
            top.iter_mut().zip(bottom).for_each(|(t, b)| t.append(b));
            learn_noise(&mut channel.noise, top);
        }
    }
}

mod channel;
mod disc;
mod motion;
mod rows;
mod walk;

#[cfg(test)]
mod reference;
#[cfg(test)]
mod tests;
