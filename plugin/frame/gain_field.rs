//! The lighting change as a smooth gain field over the frame: per RGB channel
//! a gain on a coarse grid round the face, bilinearly interpolated as the
//! frame is pasted, `(v' + ε) = g · (v + ε)`. YUV frames take the same change
//! worked out on each pixel's own Y, Cb and Cr ([`yuv`]).
//!
//! The field holds the network's change (continued beyond the crop as it is at
//! the crop's nearest point) faded out round the person: whole within a
//! silhouette of head and shoulders ([`Silhouette`]: a circle of
//! [`INNER_RADIUS`] of the crop's side about the crop's centre, joined by a
//! neck to a band as wide as the shoulders that runs down out of the frame),
//! falling by smoothstep to nothing `feather` pixels beyond it. The
//! silhouette's edge is rounded everywhere, so it has no straight edge, and its
//! fade is the only place where the change ends.
//!
//! Built per frame on a grid of [`CELLS_PER_CROP`] cells across the crop (a
//! few thousand cells, more where the shoulders' band runs down a frame many
//! crops tall, an `exp` each per channel); the paste interpolates a
//! grid row across the plane once per cell's worth of rows and then runs one
//! multiply-add per byte, with no division or call in the loop.

pub(super) mod yuv;

use std::ops::Range;

use super::{Crop, FacePlace, FrameMut, LightingChange, PixelFormat, YuvMatrix, round_to_u8};
use crate::parallel::beside;
use yuv::YuvChange;

/// Grid cells across the crop's side: a cell is three of the 96 px network's
/// pixels, and the face box about eleven cells across, so the face's finest
/// shading (`FACE_DETAIL_SMOOTHING`, a network pixel) reaches the frame
/// sampled at about its own scale. At 16 cells, a cell of six network pixels,
/// the portrait's key swap read -9.8 and its strength 14.5 against -10.2 and
/// 15.4 (`examples/target_lights direction`); the paste costs 0.2-0.4 ms a
/// frame more at 720p and 1080p (`examples/paste_speed`, 2026-12-08).
const CELLS_PER_CROP: f32 = 32.0;

/// Radius, as a fraction of the crop's side, about the crop's centre within
/// which the change shows whole: the head (the crop is 2.9 face heights, its
/// centre a little above the face's).
pub const INNER_RADIUS: f32 = 0.25;

/// The body's shape under the face, in face heights (BlazeFace's box,
/// hairline to chin): its top edge this far below the face's centre, under
/// the chin and neck ...
const SHOULDERS_BELOW: f32 = 0.9;
/// ... half its width: shoulders are about two face heights across, and the
/// band is wider so that the tops of the arms, and shoulders the face box
/// lags behind as the person turns, stay within it ...
const BODY_HALF_WIDTH: f32 = 1.3;
/// ... the radius of its top corners, the shoulders' curve ...
const SHOULDER_RADIUS: f32 = 0.6;
/// ... half the width of the neck that joins it to the head ...
const NECK_HALF_WIDTH: f32 = 0.35;
/// ... and how far head, neck and body are rounded into each other.
const NECK_BLEND: f32 = 0.5;

/// Frames of fewer rows are pasted on one thread: handing half to a second
/// costs about 20 µs (`cargo run --release --example paste_speed`, its last
/// line), a 20th of a 480p frame's paste.
const SPLIT_HEIGHT: usize = 480;

/// The `ε` of the gain applied to the frame, `(v' + ε) = g · (v + ε)`, in
/// 8-bit levels: two. A pure gain would multiply the noise and rounding of
/// near-black pixels, so their change would differ from their neighbours'; a
/// larger one lifts black towards grey, a haze over dark hair and backgrounds.
const LIFT: f32 = 2.0;

/// The change on a grid of `columns` × `rows` cells, cell (0, 0)'s corner at
/// `origin` in frame pixels, each `cell` frame pixels wide: per RGB channel a
/// gain.
pub(super) struct GainField {
    columns: usize,
    rows: usize,
    origin: [f32; 2],
    cell: f32,
    gain: [Vec<f32>; 3],
    /// For YUV frames: the change in Y'CbCr terms, and per cell the gain of
    /// luma where the pixel has no colour (the luma-weighted mean of the three).
    yuv: Option<(YuvChange, Vec<f32>)>,
    /// Per grid row, the first and last cell that changes anything; None when
    /// none does.
    spans: Vec<Option<(usize, usize)>>,
    /// Where the paste adds no dither.
    undithered: Undithered,
}

impl GainField {
    /// The field of `change` round `crop` of a `width` × `height` frame of
    /// `format`, shown at `strength` in [0, 1] and fading out over `feather`
    /// pixels.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        change: &LightingChange,
        crop: Crop,
        feather: usize,
        strength: f32,
        format: PixelFormat,
        matrix: YuvMatrix,
        (width, height): (usize, usize),
    ) -> GainField {
        let side = crop.size.max(1) as f32;
        let cell = side / CELLS_PER_CROP;
        let feather = feather as f32;
        let silhouette = Silhouette::new(crop, change.face, feather);
        // The grid covers the fade round the silhouette and one identity cell
        // beyond it, so interpolation past its edge (clamped to it) changes
        // nothing; where the frame ends first, it ends with the frame.
        let (low, high) = silhouette.bounds();
        let span = |axis: usize, extent: usize| {
            let first = (low[axis] / cell - 1.0).floor().max(0.0);
            let last = (high[axis] / cell + 1.0)
                .ceil()
                .min((extent as f32 / cell).ceil());
            (first, ((last - first) as usize).max(2))
        };
        let ((x0, columns), (y0, rows)) = (span(0, width), span(1, height));
        let origin = [x0 * cell, y0 * cell];
        let strength = strength.clamp(0.0, 1.0);
        let cells = columns * rows;
        let mut gain = [0; 3].map(|_| vec![1f32; cells]);
        let yuv_change = format.is_yuv().then(|| YuvChange::new(matrix));
        let mut luma_gain = vec![1f32; if format.is_yuv() { cells } else { 0 }];
        let mut spans = vec![None; rows];
        for (gy, row_span) in spans.iter_mut().enumerate() {
            for gx in 0..columns {
                let p = [
                    origin[0] + (gx as f32 + 0.5) * cell,
                    origin[1] + (gy as f32 + 0.5) * cell,
                ];
                let weight = strength * fade(silhouette.distance(p), feather);
                if weight <= 0.0 {
                    continue;
                }
                // Where in the network's image: the crop's nearest point.
                let u = [p[0] - crop.x as f32, p[1] - crop.y as f32].map(|v| v / side);
                let g = change
                    .log_gain
                    .each_ref()
                    .map(|g| (weight * change.sample(g, u)).exp());
                let i = gy * columns + gx;
                for c in 0..3 {
                    gain[c][i] = g[c];
                }
                if let Some(yuv) = &yuv_change {
                    luma_gain[i] = yuv.luma_gain(g);
                }
                *row_span = Some(row_span.map_or((gx, gx), |(first, _)| (first, gx)));
            }
        }
        GainField {
            columns,
            rows,
            origin,
            cell,
            gain,
            yuv: yuv_change.map(|y| (y, luma_gain)),
            spans,
            undithered: Undithered::new(silhouette.head, silhouette.head_radius),
        }
    }

    /// Bilinear taps from the `count` samples of a plane, each `subsample`
    /// frame pixels wide, onto the grid along axis `axis` (0: x, 1: y): per
    /// sample, the lower cell and the weight of the upper one.
    pub(super) fn taps(&self, count: usize, subsample: usize, axis: usize) -> Vec<(usize, f32)> {
        let cells = [self.columns, self.rows][axis];
        let last = (cells - 1) as f32;
        (0..count)
            .map(|i| {
                let frame = (i as f32 + 0.5) * subsample as f32;
                let p = ((frame - self.origin[axis]) / self.cell - 0.5).clamp(0.0, last);
                let lo = (p.floor() as usize).min(cells - 2);
                (lo, p - lo as f32)
            })
            .collect()
    }

    /// Applies the field to `frame`. Each row's change reads that row
    /// alone, so the bottom half of a frame of [`SPLIT_HEIGHT`] rows or more
    /// is pasted on another thread while this one pastes the top.
    pub(super) fn paste(&self, frame: &mut FrameMut) {
        let height = frame.height;
        if height < SPLIT_HEIGHT {
            return self.paste_rows(frame, 0..height);
        }
        let split = height / 4 * 2;
        let [mut top, mut bottom] = frame.split_rows(split);
        beside(
            || self.paste_rows(&mut bottom, split..height),
            || self.paste_rows(&mut top, 0..split),
        );
    }

    /// Applies the field to frame rows `rows` (even where it starts) of
    /// `frame`, whose planes start at the first of them.
    fn paste_rows(&self, frame: &mut FrameMut, rows: Range<usize>) {
        if let Some((yuv, luma_gain)) = &self.yuv {
            return self.paste_yuv(yuv, luma_gain, frame, rows);
        }
        let size = (frame.width, frame.height);
        for pass in frame.format.passes() {
            let (data, stride) = (&mut *frame.planes[pass.plane].0, frame.planes[pass.plane].1);
            let sub = pass.subsample;
            let plane = (size.0.div_ceil(sub), size.1.div_ceil(sub));
            let rows = rows.start / sub..rows.end.div_ceil(sub);
            match *pass.lanes {
                [a] => self.paste_plane([a], data, stride, plane, sub, rows),
                [a, b] => self.paste_plane([a, b], data, stride, plane, sub, rows),
                [a, b, c] => self.paste_plane([a, b, c], data, stride, plane, sub, rows),
                [a, b, c, d] => self.paste_plane([a, b, c, d], data, stride, plane, sub, rows),
                _ => unreachable!("no format has {} bytes a pixel", pass.lanes.len()),
            }
        }
    }

    /// The columns of a plane (taps `taps_x`) that read a changing cell in
    /// grid rows `ly` and `ly + 1`; None when neither changes anything.
    /// Elsewhere all four cells a pixel reads are the identity, which leaves
    /// its bytes as they are.
    fn changed_columns(&self, taps_x: &[(usize, f32)], ly: usize) -> Option<(usize, usize)> {
        let span = match (self.spans[ly], self.spans[ly + 1]) {
            (None, None) => return None,
            (Some(a), None) | (None, Some(a)) => a,
            (Some(a), Some(b)) => (a.0.min(b.0), a.1.max(b.1)),
        };
        // Taps rise with x.
        let first = taps_x.partition_point(|&(lx, _)| lx + 1 < span.0);
        let end = taps_x.partition_point(|&(lx, _)| lx <= span.1);
        (first < end).then_some((first, end))
    }

    /// Applies the field to rows `rows` of a plane of `width` × `height`
    /// pixels whose `BPP` bytes a pixel hold the channels `lanes` (`data`
    /// starts at the first of those rows): each byte `v` becomes `g · v + o`,
    /// dithered. Each row is one flat run of bytes ("lanes"), whatever
    /// channels they hold, so the loop over it vectorises.
    #[allow(clippy::too_many_arguments)]
    fn paste_plane<const BPP: usize>(
        &self,
        lanes: [Option<usize>; BPP],
        data: &mut [u8],
        stride: usize,
        (width, height): (usize, usize),
        subsample: usize,
        rows: Range<usize>,
    ) {
        let (taps_x, taps_y) = (
            self.taps(width, subsample, 0),
            self.taps(height, subsample, 1),
        );
        // The columns any row changes: grid rows are interpolated over these only.
        let Some((first, end)) = (0..self.rows - 1)
            .filter_map(|ly| self.changed_columns(&taps_x, ly))
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
        else {
            return;
        };
        let taps_x = &taps_x[first..end];
        let mut field_rows = FieldRows::new(taps_x.len() * BPP);
        let dithers = dither_rows(first, taps_x.len(), BPP);
        let xs = pixel_xs(first, taps_x.len(), subsample);
        let zeros = vec![0f32; taps_x.len() * BPP];
        for (y, &(ly, ty)) in taps_y.iter().enumerate().take(rows.end).skip(rows.start) {
            let Some((a, b)) = self.changed_columns(taps_x, ly) else {
                continue;
            };
            let (top, bottom) =
                field_rows.at(ly, |r, out| self.interpolate_row(r, lanes, taps_x, out));
            let start = (y - rows.start) * stride + first * BPP;
            let row = &mut data[start..start + taps_x.len() * BPP];
            let span = self
                .undithered
                .span(&xs, (y as f32 + 0.5) * subsample as f32);
            let runs = dither_runs(
                a * BPP..b * BPP,
                span.start * BPP..span.end * BPP,
                &dithers[y % DITHER],
                &zeros,
            );
            for (lanes, dither) in runs {
                gain_row(
                    &mut row[lanes.clone()],
                    ty,
                    (&top.gain[lanes.clone()], &bottom.gain[lanes]),
                    LIFT,
                    dither,
                );
            }
        }
    }

    /// Grid row `r` interpolated across the plane's columns (taps `taps`) at
    /// every lane: the horizontal half of the bilinear upsampling. Padding
    /// lanes keep a gain of 1, which leaves their bytes as they are.
    fn interpolate_row<const BPP: usize>(
        &self,
        r: usize,
        lanes: [Option<usize>; BPP],
        taps: &[(usize, f32)],
        out: &mut FieldRow,
    ) {
        // A lane at a time, so the loop over the taps has no branch.
        for (lane, channel) in lanes.iter().enumerate() {
            if let Some(c) = *channel {
                let out = out.gain.iter_mut().skip(lane).step_by(BPP);
                self.interpolate_map_row(&self.gain[c], r, taps, out);
            }
        }
    }

    /// Row `r` of `map` (a grid of the field's cells) interpolated at `taps`
    /// into `out`.
    fn interpolate_map_row<'a>(
        &self,
        map: &[f32],
        r: usize,
        taps: &[(usize, f32)],
        out: impl Iterator<Item = &'a mut f32>,
    ) {
        let m = &map[r * self.columns..(r + 1) * self.columns];
        for (&(lx, tx), o) in taps.iter().zip(out) {
            *o = m[lx] + (m[lx + 1] - m[lx]) * tx;
        }
    }

    /// `map` (a grid of the field's cells) at taps `x` and `y` (from
    /// [`GainField::taps`]), in exactly the operations of the paste.
    #[cfg(test)]
    pub(super) fn sample(
        &self,
        map: &[f32],
        (lx, tx): (usize, f32),
        (ly, ty): (usize, f32),
    ) -> f32 {
        let row = |r: usize| {
            let m = &map[r * self.columns..(r + 1) * self.columns];
            m[lx] + (m[lx + 1] - m[lx]) * tx
        };
        row(ly) * (1.0 - ty) + row(ly + 1) * ty
    }

    /// Byte `v` of RGB channel `c` at a pixel with taps `x` and `y` (from
    /// [`GainField::taps`]) and dither `dither`, relit: the field sampled on
    /// its own, for the reference paste.
    #[cfg(test)]
    pub(super) fn at(&self, c: usize, v: u8, x: (usize, f32), y: (usize, f32), dither: f32) -> f32 {
        let gain = self.sample(&self.gain[c], x, y);
        gain * (v as f32 + LIFT) - LIFT + dither
    }

    /// Whether the paste adds its dither at frame point (`x`, `y`), for the
    /// reference paste.
    #[cfg(test)]
    pub(super) fn dithers_at(&self, x: f32, y: f32) -> bool {
        !self.undithered.holds(x, y - self.undithered.centre[1])
    }
}

/// Radius, as a share of [`INNER_RADIUS`], of the disc about the field's
/// centre where the paste adds no dither. The dither is for flat dark areas,
/// where a smooth change would otherwise round to bands: the room and the
/// fade. Over the face it is mostly noise: the face is textured and lit, and
/// on its near-black pixels (eyes, brows, hair at the brow) half a level is a
/// large ratio that differs from channel to channel, grain in the skin's
/// colour. Left out there, the film clip's mottling over the face fell from
/// 2.50% to 1.86% and its largest box edge went from 9.5% to 9.6%
/// (`examples/real_footage.rs`); with the disc at the inner circle itself the
/// mottling fell to 1.99% only, and at 1.4 times it the box edge rose to 10.3%.
/// The disc's edge is hard: the dither has no mean, so its edge is no step in
/// the change, and a fade would cost a distance a pixel.
const UNDITHERED_RADIUS: f32 = 1.2;

/// The disc where the paste adds no dither, in frame pixels.
struct Undithered {
    centre: [f32; 2],
    radius: f32,
}

impl Undithered {
    fn new(centre: [f32; 2], inner: f32) -> Undithered {
        Undithered {
            centre,
            radius: UNDITHERED_RADIUS * inner,
        }
    }

    /// Whether the disc holds frame x `x` on a row `dy` from its centre.
    #[inline(always)]
    fn holds(&self, x: f32, dy: f32) -> bool {
        let dx = x - self.centre[0];
        dx * dx + dy * dy < self.radius * self.radius
    }

    /// The pixels at frame x `xs` (rising, evenly spaced) of the row at frame
    /// y `y` that the disc holds: the same test, pixel for pixel, as
    /// [`Undithered::holds`]. Each end is first placed where the circle
    /// crosses the row, then moved pixel by pixel until the test agrees: a
    /// binary search per row, each step waiting on the last, cost more than
    /// the rest of a packed row's setup.
    fn span(&self, xs: &[f32], y: f32) -> Range<usize> {
        let dy = y - self.centre[1];
        let reach = (self.radius * self.radius - dy * dy).max(0.0).sqrt();
        let index = |x: f32| match xs {
            [first, second, ..] => ((x - first) / (second - first)).max(0.0) as usize,
            _ => 0,
        };
        let middle = settle(xs, 0..xs.len(), index(self.centre[0]), |x| {
            x < self.centre[0]
        });
        let first = settle(xs, 0..middle, index(self.centre[0] - reach), |x| {
            !self.holds(x, dy)
        });
        let end = settle(xs, middle..xs.len(), index(self.centre[0] + reach), |x| {
            self.holds(x, dy)
        });
        first..end.max(first)
    }
}

/// `within.start + xs[within].partition_point(pred)`, found by walking from
/// `guess` (`pred` true for a prefix of `xs[within]`, false after it).
fn settle(xs: &[f32], within: Range<usize>, guess: usize, pred: impl Fn(f32) -> bool) -> usize {
    let mut at = guess.clamp(within.start, within.end);
    while at > within.start && !pred(xs[at - 1]) {
        at -= 1;
    }
    while at < within.end && pred(xs[at]) {
        at += 1;
    }
    at
}

/// `within`, lanes of a row, split where `span` (lanes the disc holds)
/// starts and ends: each part with the dither it takes, `pattern`'s or none
/// (`zeros`), in order.
fn dither_runs<'a>(
    within: Range<usize>,
    span: Range<usize>,
    pattern: &'a [f32],
    zeros: &'a [f32],
) -> impl Iterator<Item = (Range<usize>, &'a [f32])> {
    let clip = move |r: Range<usize>| r.start.max(within.start)..r.end.min(within.end);
    let (a, b) = (span.start, span.end);
    [
        (clip(0..a), pattern),
        (clip(a..b), zeros),
        (clip(b..usize::MAX), pattern),
    ]
    .into_iter()
    .filter(|(r, _)| !r.is_empty())
    .map(|(r, dither)| (r.clone(), &dither[r]))
}

/// Where the change shows whole, in frame pixels: the head, a circle of
/// [`INNER_RADIUS`] of the crop about its centre, joined by a neck to the
/// shoulders and body below the face, a band of rounded top corners that runs
/// down out of the frame, all three rounded into each other. The light that falls on a face falls on its neck and
/// shoulders too: a head relit on a body left as filmed reads as a mask.
///
/// Against the circle alone, on the simulator's `call` against exact truth
/// (`examples/target_lights measure --frames 60 --model models/starter`),
/// every target came closer but rim, studio 12.92 to 10.41, warm-key-left
/// 7.22 to 6.95, neon 12.53 to 11.18, rim 5.37 as before; on real footage the box
/// edges and the face's mottling stayed as they were (`benchmark
/// --quality`). The body's shape is a person's, not the picture's: where
/// arms or hair leave it, they keep their light, and the wall beside the
/// shoulders takes part of the change in the fade, as round the head.
pub(super) struct Silhouette {
    head: [f32; 2],
    head_radius: f32,
    /// The middle of the body's top edge, half its width, and the radius of
    /// its top corners, the shoulders.
    body_top: [f32; 2],
    body_half_width: f32,
    shoulder_radius: f32,
    /// Half the width of the neck, from the head's centre to the body's top.
    neck_half_width: f32,
    /// How far the union is rounded where its parts meet.
    neck_blend: f32,
    feather: f32,
}

impl Silhouette {
    pub(super) fn new(crop: Crop, face: FacePlace, feather: f32) -> Silhouette {
        let side = crop.size.max(1) as f32;
        let face_height = face.height * side;
        let face_centre = [
            crop.x as f32 + face.centre[0] * side,
            crop.y as f32 + face.centre[1] * side,
        ];
        Silhouette {
            head: [crop.x as f32 + side / 2.0, crop.y as f32 + side / 2.0],
            head_radius: INNER_RADIUS * side,
            body_top: [
                face_centre[0],
                face_centre[1] + SHOULDERS_BELOW * face_height,
            ],
            body_half_width: BODY_HALF_WIDTH * face_height,
            shoulder_radius: SHOULDER_RADIUS * face_height,
            neck_half_width: NECK_HALF_WIDTH * face_height,
            neck_blend: NECK_BLEND * face_height,
            feather,
        }
    }

    /// Signed distance from frame point `p` to the silhouette's edge,
    /// negative inside.
    pub(super) fn distance(&self, p: [f32; 2]) -> f32 {
        let head = (p[0] - self.head[0]).hypot(p[1] - self.head[1]) - self.head_radius;
        // A box's signed distance, its top corners rounded and its bottom
        // below any frame.
        let round = self.shoulder_radius;
        let qx = (p[0] - self.body_top[0]).abs() - (self.body_half_width - round);
        let qy = (self.body_top[1] + round) - p[1];
        let body = qx.max(0.0).hypot(qy.max(0.0)) + qx.max(qy).min(0.0) - round;
        // A capsule from the head's centre to the body's top: however far
        // below the head the crop rule puts the shoulders, they are joined.
        let along = [
            self.body_top[0] - self.head[0],
            self.body_top[1] - self.head[1],
        ];
        let t = ((p[0] - self.head[0]) * along[0] + (p[1] - self.head[1]) * along[1])
            / (along[0] * along[0] + along[1] * along[1]).max(f32::EPSILON);
        let t = t.clamp(0.0, 1.0);
        let neck = (p[0] - self.head[0] - t * along[0]).hypot(p[1] - self.head[1] - t * along[1])
            - self.neck_half_width;
        let k = self.neck_blend;
        smooth_min(smooth_min(head, neck, k), body, k)
    }

    /// The frame box, low and high corners, outside which nothing changes.
    /// Each of the two smooth minima reaches up to a quarter of its rounding
    /// beyond the plain union (the neck lies within the head's and body's
    /// reach).
    pub(super) fn bounds(&self) -> ([f32; 2], [f32; 2]) {
        let slack = 0.5 * self.neck_blend;
        let head_reach = self.head_radius + self.feather + slack;
        let body_reach = self.body_half_width + self.feather + slack;
        (
            [
                (self.head[0] - head_reach).min(self.body_top[0] - body_reach),
                (self.head[1] - head_reach).min(self.body_top[1] - self.feather - slack),
            ],
            [
                (self.head[0] + head_reach).max(self.body_top[0] + body_reach),
                f32::INFINITY,
            ],
        )
    }
}

/// The smaller of `a` and `b`, rounded over `k` where they meet (the
/// polynomial smooth minimum): the union of two shapes has no crease there.
fn smooth_min(a: f32, b: f32, k: f32) -> f32 {
    if k <= 0.0 {
        return a.min(b);
    }
    let h = (0.5 + 0.5 * (b - a) / k).clamp(0.0, 1.0);
    b + (a - b) * h - k * h * (1.0 - h)
}

/// How much of the change shows `distance` pixels beyond the silhouette:
/// 1 within it, falling by smoothstep (no kink where the fade starts or ends,
/// which the eye reads as an edge) to 0 at `feather` pixels beyond.
fn fade(distance: f32, feather: f32) -> f32 {
    if distance <= 0.0 {
        return 1.0;
    }
    if feather <= 0.0 {
        return 0.0;
    }
    let t = 1.0 - (distance / feather).min(1.0);
    t * t * (3.0 - 2.0 * t)
}

/// A grid row interpolated to every lane of a plane row: the gains.
struct FieldRow {
    gain: Vec<f32>,
}

/// Two consecutive `FieldRow`s, kept while the plane rows they serve (about a
/// cell's worth) go by. Row `r` lives in slot `r % 2`.
struct FieldRows {
    held: [Option<usize>; 2],
    slots: [FieldRow; 2],
}

impl FieldRows {
    fn new(lanes: usize) -> FieldRows {
        let row = || FieldRow {
            // Padding lanes keep a gain of 1.
            gain: vec![1.0; lanes],
        };
        FieldRows {
            held: [None; 2],
            slots: [row(), row()],
        }
    }

    /// Rows `ly` and `ly + 1`, filling in with `fill` those not held.
    fn at(&mut self, ly: usize, fill: impl Fn(usize, &mut FieldRow)) -> (&FieldRow, &FieldRow) {
        for r in [ly, ly + 1] {
            if self.held[r % 2] != Some(r) {
                fill(r, &mut self.slots[r % 2]);
                self.held[r % 2] = Some(r);
            }
        }
        (&self.slots[ly % 2], &self.slots[(ly + 1) % 2])
    }
}

/// Relights one row of lanes: the vertical half of the bilinear upsampling of
/// the gain, then `g · (v + p) − p` dithered ([`dither`], or any other
/// addition) and rounded, in exactly the operations of [`GainField::at`].
pub(super) fn gain_row(
    row: &mut [u8],
    ty: f32,
    gain: (&[f32], &[f32]),
    pivot: f32,
    dither: &[f32],
) {
    // AVX2, where the CPU has it, takes 32 samples at a time. The results are
    // the same: its lanes run the portable loop's IEEE operations in the same
    // order, written out by hand (and Rust never fuses a multiply and an add
    // on its own).
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { gain_row_avx2(row, ty, gain, pivot, dither) };
    }
    gain_row_portable(row, ty, gain, pivot, dither)
}

/// `gain_row_portable` in AVX2, 32 samples at a time: the same operations
/// in the same order on each lane, with `round_to_u8`'s rounding, and the
/// results packed to bytes 32 at once. Built by the compiler from the
/// portable loop, each 8 results took five byte shuffles to pack, which
/// bounded the loop (`cargo run --release --example paste_speed`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn gain_row_avx2(row: &mut [u8], ty: f32, gain: (&[f32], &[f32]), pivot: f32, dither: &[f32]) {
    use std::arch::x86_64::*;
    let n = row.len();
    let (top, bottom, dither) = (&gain.0[..n], &gain.1[..n], &dither[..n]);
    let whole = n - n % avx2::BLOCK;
    let (uy, ty_v) = (_mm256_set1_ps(1.0 - ty), _mm256_set1_ps(ty));
    let pivot_v = _mm256_set1_ps(pivot);
    for k in (0..whole).step_by(avx2::BLOCK) {
        let mut rounded = [_mm256_setzero_si256(); avx2::BLOCK / avx2::LANES];
        for (j, out) in rounded.iter_mut().enumerate() {
            let i = k + j * avx2::LANES;
            // SAFETY: i + LANES <= whole <= n, the length of every slice read.
            *out = unsafe {
                let load = |s: &[f32]| _mm256_loadu_ps(s.as_ptr().add(i));
                let bytes = _mm_loadl_epi64(row.as_ptr().add(i).cast());
                let v = _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(bytes));
                let gain = _mm256_add_ps(
                    _mm256_mul_ps(load(top), uy),
                    _mm256_mul_ps(load(bottom), ty_v),
                );
                let relit = _mm256_sub_ps(_mm256_mul_ps(gain, _mm256_add_ps(v, pivot_v)), pivot_v);
                avx2::round_to_u8(_mm256_add_ps(relit, load(dither)))
            };
        }
        avx2::store_bytes(&mut row[k..k + avx2::BLOCK], rounded);
    }
    let tail = whole..n;
    gain_row_portable(
        &mut row[tail.clone()],
        ty,
        (&top[tail.clone()], &bottom[tail.clone()]),
        pivot,
        &dither[tail],
    )
}

/// The AVX2 pieces the paste's loops share: `round_to_u8` on 8 lanes, and 32
/// of its results packed to bytes.
#[cfg(target_arch = "x86_64")]
pub(super) mod avx2 {
    use std::arch::x86_64::*;

    /// Samples a loop takes at a time: 32 bytes, one store.
    pub(in crate::frame) const BLOCK: usize = 32;
    /// f32 lanes of a vector.
    pub(in crate::frame) const LANES: usize = 8;

    /// `round_to_u8` of each lane, in the lane's low byte: the same
    /// operations, so the same results (NaN to 0, ties away from zero).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(in crate::frame) fn round_to_u8(x: __m256) -> __m256i {
        const SHIFT: f32 = 8_388_608.0;
        let shift = _mm256_set1_ps(SHIFT);
        // max and min return their second operand for NaN, so NaN becomes 0
        // as there.
        let c = _mm256_min_ps(_mm256_max_ps(x, _mm256_setzero_ps()), _mm256_set1_ps(255.0));
        let shifted = _mm256_add_ps(c, shift);
        let tie = _mm256_cmp_ps::<_CMP_EQ_OQ>(
            _mm256_sub_ps(c, _mm256_sub_ps(shifted, shift)),
            _mm256_set1_ps(0.5),
        );
        // The whole number in the sum's low bits, plus one at a tie (the
        // comparison's all-ones lanes are −1).
        let units = _mm256_sub_epi32(
            _mm256_castps_si256(shifted),
            _mm256_set1_epi32(SHIFT.to_bits() as i32),
        );
        _mm256_sub_epi32(units, _mm256_castps_si256(tie))
    }

    /// Four vectors of `round_to_u8` results, in order, into `out`'s 32 bytes.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(in crate::frame) fn store_bytes(out: &mut [u8], rounded: [__m256i; BLOCK / LANES]) {
        assert_eq!(out.len(), BLOCK);
        let words = [
            _mm256_packus_epi32(rounded[0], rounded[1]),
            _mm256_packus_epi32(rounded[2], rounded[3]),
        ];
        // The packs work within each 128-bit half: this puts the 4-byte
        // groups back in order.
        let order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
        let bytes = _mm256_permutevar8x32_epi32(_mm256_packus_epi16(words[0], words[1]), order);
        // SAFETY: `out` holds 32 bytes, checked above.
        unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), bytes) };
    }
}

// Always inlined, so that `gain_row_avx2` holds a copy built for AVX2.
#[inline(always)]
pub(super) fn gain_row_portable(
    row: &mut [u8],
    ty: f32,
    gain: (&[f32], &[f32]),
    pivot: f32,
    dither: &[f32],
) {
    let uy = 1.0 - ty;
    let n = row.len();
    let (top, bottom, dither) = (&gain.0[..n], &gain.1[..n], &dither[..n]);
    for k in 0..n {
        let gain = top[k] * uy + bottom[k] * ty;
        row[k] = round_to_u8(gain * (row[k] as f32 + pivot) - pivot + dither[k]);
    }
}

/// Side of the ordered dither's pattern.
const DITHER: usize = 4;

/// The 4 × 4 Bayer pattern: each value once, neighbours far apart.
const BAYER: [u8; DITHER * DITHER] = [0, 8, 2, 10, 12, 4, 14, 6, 3, 11, 1, 9, 15, 7, 13, 5];

/// What is added to a pasted value at plane pixel (x, y) before rounding, in
/// (−0.5, 0.5): an ordered dither. A smooth change over a flat dark area
/// otherwise rounds to bands, whose borders (a level at 4 is a change of a
/// sixth) show where the field crosses each half level.
pub(super) fn dither(x: usize, y: usize) -> f32 {
    (BAYER[(y % DITHER) * DITHER + x % DITHER] as f32 + 0.5) / (DITHER * DITHER) as f32 - 0.5
}

/// The frame x of each of the `count` pixels from plane column `first`,
/// `subsample` frame pixels each.
fn pixel_xs(first: usize, count: usize, subsample: usize) -> Vec<f32> {
    (first..first + count)
        .map(|x| (x as f32 + 0.5) * subsample as f32)
        .collect()
}

/// Per row of the pattern, the dither of every lane of the `count` pixels
/// from column `first` of a row, `lanes` a pixel.
fn dither_rows(first: usize, count: usize, lanes: usize) -> [Vec<f32>; DITHER] {
    std::array::from_fn(|y| {
        (0..count * lanes)
            .map(|lane| dither(first + lane / lanes, y))
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::{Undithered, pixel_xs};

    #[test]
    fn the_undithered_span_is_every_pixel_the_disc_holds() {
        // Discs inside the row, beyond either end, and of no size; rows
        // through them, tangent to them and beyond them.
        for (centre, radius) in [
            ([50.3, 20.0], 13.7),
            ([-5.0, 20.0], 9.0),
            ([130.0, 20.0], 30.0),
            ([40.0, 20.0], 0.0),
        ] {
            let disc = Undithered { centre, radius };
            for (first, count, subsample) in
                [(0, 60, 1), (7, 60, 1), (3, 40, 2), (9, 1, 2), (0, 0, 1)]
            {
                let xs = pixel_xs(first, count, subsample);
                for y in -20..60 {
                    let y = y as f32 + 0.5;
                    let held: Vec<usize> = (0..count)
                        .filter(|&i| disc.holds(xs[i], y - centre[1]))
                        .collect();
                    let span = disc.span(&xs, y);
                    match (held.first(), held.last()) {
                        (Some(&a), Some(&b)) => {
                            assert_eq!(span, a..b + 1, "{centre:?} {radius} y {y}")
                        }
                        _ => assert!(span.is_empty(), "{centre:?} {radius} y {y}: {span:?}"),
                    }
                }
            }
        }
    }
}
