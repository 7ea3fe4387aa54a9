//! The denoising written plainly, kept to hold the fast one to: each step a
//! whole map of the area at a time, as `denoise.rs` first did it. The fast
//! one must give the same bytes and the same filtered detail.

use super::super::{FrameMut, round_to_u8};
use super::channel::{NO_DETAIL, restored, stored};
use super::disc::Disc;
use super::motion::{band, new_share, per_band};
use super::walk::{DITHER_ROWS, PlaneView, sample_positions};
use super::{BANDS, MOTION_RADIUS, NOISE_SAMPLES, SPLIT_RADIUS};

/// What the plain denoiser keeps of one channel (`ChannelState`).
#[derive(Default)]
pub struct ReferenceChannel {
    area: [usize; 4],
    pub detail: Vec<i16>,
    pub noise: [Option<f32>; BANDS],
}

#[derive(Default)]
struct Scratch {
    values: Vec<f32>,
    past: Vec<f32>,
    smooth: Vec<f32>,
    detail: Vec<f32>,
    difference: Vec<f32>,
    squared: Vec<f32>,
    motion: Vec<f32>,
    rows: Vec<f32>,
    seen: [Vec<f32>; BANDS],
    xs: Vec<f32>,
    weight: Vec<f32>,
    relit: Vec<f32>,
    dither: [Vec<f32>; DITHER_ROWS],
}

/// `DetailDenoiser` written plainly.
#[derive(Default)]
pub struct ReferenceDenoiser {
    stream: Option<(super::PixelFormat, usize, usize)>,
    pub channels: Vec<ReferenceChannel>,
    scratch: Scratch,
}

impl ReferenceDenoiser {
    pub fn reset(&mut self) {
        self.stream = None;
        self.channels.clear();
    }

    pub fn apply(
        &mut self,
        frame: &mut FrameMut,
        crop: super::Crop,
        feather: usize,
        strength: f32,
    ) {
        let stream = Some((frame.format, frame.width, frame.height));
        if self.stream != stream {
            self.reset();
            self.stream = stream;
        }
        let disc = Disc::new(crop, feather, strength);
        let mut k = 0;
        for pass in frame.format.passes() {
            let (data, stride) = (&mut *frame.planes[pass.plane].0, frame.planes[pass.plane].1);
            let sub = pass.subsample;
            let plane = PlaneView {
                size: (frame.width.div_ceil(sub), frame.height.div_ceil(sub)),
                stride,
                bytes: pass.lanes.len(),
                subsample: sub,
            };
            for (lane, channel) in pass.lanes.iter().enumerate() {
                if channel.is_none() {
                    continue;
                }
                if self.channels.len() <= k {
                    self.channels.push(ReferenceChannel::default());
                }
                self.channels[k].filter(data, &plane, lane, &disc, &mut self.scratch);
                k += 1;
            }
        }
    }
}

impl ReferenceChannel {
    /// Filters byte `lane` of every sample of `plane` that `disc` reaches,
    /// working in `s`.
    fn filter(
        &mut self,
        data: &mut [u8],
        plane: &PlaneView,
        lane: usize,
        disc: &Disc,
        s: &mut Scratch,
    ) {
        let area = disc.area(plane.subsample, plane.size);
        let [x0, y0, w, h] = area;
        if w == 0 || h == 0 || disc.strength <= 0.0 {
            // Nothing shown: the past no longer matches what is shown next.
            self.detail.clear();
            self.area = [0; 4];
            return;
        }
        self.move_to(area);
        let n = w * h;
        // Each step below is a flat loop over whole slices, so that it vectorises.
        s.values.resize(n, 0.0);
        for (y, row) in s.values.chunks_exact_mut(w).enumerate() {
            let start = (y0 + y) * plane.stride + x0 * plane.bytes + lane;
            let bytes = data[start..].iter().step_by(plane.bytes);
            row.iter_mut().zip(bytes).for_each(|(v, &b)| *v = b as f32);
        }
        window_mean(&s.values, (w, h), SPLIT_RADIUS, &mut s.smooth);
        // The detail, and its difference from the filtered detail of the
        // frame before: NaN where there is none.
        s.past.clear();
        s.past
            .extend(self.detail.iter().map(|&kept| restored(kept, f32::NAN)));
        for buffer in [&mut s.detail, &mut s.difference, &mut s.squared] {
            buffer.resize(n, 0.0);
        }
        for (((d, (&v, &smooth)), difference), past) in (s.detail.iter_mut())
            .zip(s.values.iter().zip(&s.smooth))
            .zip(s.difference.iter_mut())
            .zip(&s.past)
        {
            *d = v - smooth;
            *difference = *d - past;
        }
        for (squared, &difference) in s.squared.iter_mut().zip(&s.difference) {
            *squared = if difference.is_nan() {
                0.0
            } else {
                difference * difference
            };
        }
        box_blur(
            &s.squared,
            (w, h),
            MOTION_RADIUS,
            &mut s.motion,
            &mut s.rows,
        );
        // The noise's level the frames before taught, or where none did yet,
        // this one; this one's motion teaches the next.
        if per_band(&self.noise).is_none() {
            learn_noise(&mut self.noise, s);
        }
        let known = per_band(&self.noise);
        learn_noise(&mut self.noise, s);
        let Some(noise) = known else {
            (self.detail.iter_mut().zip(&s.detail)).for_each(|(kept, &d)| *kept = stored(d));
            return;
        };
        // Over the noise, per band: what a local mean squared difference is
        // compared with. The share of the new frame goes into `squared`.
        let inverse = noise.map(|n| 1.0 / n);
        for (share, (&motion, &smooth)) in s.squared.iter_mut().zip(s.motion.iter().zip(&s.smooth))
        {
            *share = new_share(motion * inverse[band(smooth)]);
        }
        for ((past, &d), (&difference, &share)) in
            (s.past.iter_mut().zip(&s.detail)).zip(s.difference.iter().zip(&s.squared))
        {
            let filtered = *past + share * difference;
            *past = if difference.is_nan() { d } else { filtered };
        }
        (self.detail.iter_mut().zip(&s.past)).for_each(|(kept, &past)| *kept = stored(past));
        let sub = plane.subsample as f32;
        sample_positions(x0, w, plane.subsample, &mut s.xs, &mut s.dither);
        s.weight.resize(w, 0.0);
        s.relit.resize(w, 0.0);
        for y in 0..h {
            disc.weights(&s.xs, ((y0 + y) as f32 + 0.5) * sub, &mut s.weight);
            let row = y * w..(y + 1) * w;
            for ((r, (&v, &dither)), ((&filtered, &d), &weight)) in (s.relit.iter_mut())
                .zip(
                    s.values[row.clone()]
                        .iter()
                        .zip(&s.dither[(y0 + y) % DITHER_ROWS]),
                )
                .zip((s.past[row.clone()].iter().zip(&s.detail[row])).zip(&s.weight))
            {
                *r = v + weight * (filtered - d) + dither;
            }
            let start = (y0 + y) * plane.stride + x0 * plane.bytes + lane;
            let bytes = data[start..].iter_mut().step_by(plane.bytes);
            for (b, &r) in bytes.zip(&s.relit) {
                *b = round_to_u8(r);
            }
        }
    }

    /// Holds `area` from now on: the filtered detail it shares with the area
    /// held so far is kept, the rest has none yet.
    fn move_to(&mut self, area: [usize; 4]) {
        if self.area == area && !self.detail.is_empty() {
            return;
        }
        let [x0, y0, w, h] = area;
        let mut detail = vec![NO_DETAIL; w * h];
        let [ox, oy, ow, oh] = self.area;
        if !self.detail.is_empty() {
            for y in y0.max(oy)..(y0 + h).min(oy + oh) {
                for x in x0.max(ox)..(x0 + w).min(ox + ow) {
                    detail[(y - y0) * w + x - x0] = self.detail[(y - oy) * ow + x - ox];
                }
            }
        }
        self.area = area;
        self.detail = detail;
    }
}

/// `learn_noise` over whole maps.
fn learn_noise(noise: &mut [Option<f32>; BANDS], scratch: &mut Scratch) {
    let seen = &mut scratch.seen;
    seen.iter_mut().for_each(Vec::clear);
    let n = scratch.motion.len();
    for i in (0..n).step_by((n / NOISE_SAMPLES).max(3)) {
        if !scratch.difference[i].is_nan() {
            seen[band(scratch.smooth[i])].push(scratch.motion[i]);
        }
    }
    super::learn_noise(noise, seen)
}

/// The mean of the whole numbers of a `w` × `h` map within `radius` each
/// way, the window shrinking at the borders, into `out`: their sum, exact,
/// times 1 over their count.
fn window_mean(field: &[f32], (w, h): (usize, usize), radius: usize, out: &mut Vec<f32>) {
    out.clear();
    for y in 0..h {
        let rows = y.saturating_sub(radius)..(y + radius + 1).min(h);
        for x in 0..w {
            let columns = x.saturating_sub(radius)..(x + radius + 1).min(w);
            let sum: f32 = (rows.clone())
                .flat_map(|r| &field[r * w + columns.start..r * w + columns.end])
                .sum();
            out.push(sum * (1.0 / (rows.len() * columns.len()) as f32));
        }
    }
}

/// A box blur of a `w` × `h` map into `out`, `radius` each way, shrinking at
/// the borders; `rows` holds the vertical pass.
fn box_blur(
    field: &[f32],
    (w, h): (usize, usize),
    radius: usize,
    out: &mut Vec<f32>,
    rows: &mut Vec<f32>,
) {
    // Both passes add whole runs of the map shifted against each other, a
    // loop that vectorises, rather than keeping a running sum, whose every
    // step waits for the one before. The radius is small.
    rows.clear();
    rows.resize(field.len(), 0.0);
    for y in 0..h {
        let (lo, hi) = (y.saturating_sub(radius), (y + radius + 1).min(h));
        let sum = &mut rows[y * w..(y + 1) * w];
        for r in lo..hi {
            add_to(sum, &field[r * w..(r + 1) * w]);
        }
        let scale = 1.0 / (hi - lo) as f32;
        sum.iter_mut().for_each(|s| *s *= scale);
    }
    out.clear();
    out.resize(field.len(), 0.0);
    let span = 2 * radius + 1;
    for (src, dst) in rows.chunks_exact(w).zip(out.chunks_exact_mut(w)) {
        if w >= span {
            // Samples with the whole window: dst[k] sums src[k - radius..=k + radius].
            let inner = &mut dst[radius..w - radius];
            for shift in 0..span {
                add_to(inner, &src[shift..shift + w + 1 - span]);
            }
            let scale = 1.0 / span as f32;
            inner.iter_mut().for_each(|s| *s *= scale);
        }
        // The borders' shrunken windows (every sample, in a map narrower than one).
        for k in (0..radius.min(w)).chain(radius.max(w.saturating_sub(radius))..w) {
            let (lo, hi) = (k.saturating_sub(radius), (k + radius + 1).min(w));
            dst[k] = src[lo..hi].iter().sum::<f32>() / (hi - lo) as f32;
        }
    }
}

/// `sum += values`, element by element.
fn add_to(sum: &mut [f32], values: &[f32]) {
    sum.iter_mut().zip(values).for_each(|(s, v)| *s += v);
}
