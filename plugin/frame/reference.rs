//! The crop and the paste written plainly, kept to hold faster ones to: one
//! channel at a time, the crop resampled horizontally first, each paste
//! sample of the gain field interpolated on its own over the whole frame.

use super::gain_field::GainField;
use super::gain_field::dither;
use super::{AreaWeights, Crop, Frame, FrameMut, LightingChange, PixelFormat, Plane};

/// For packed RGB formats: byte offsets of R, G and B and bytes per pixel.
pub fn packed(format: PixelFormat) -> Option<([usize; 3], usize)> {
    match format {
        PixelFormat::Rgba | PixelFormat::Rgbx => Some(([0, 1, 2], 4)),
        PixelFormat::Bgra | PixelFormat::Bgrx => Some(([2, 1, 0], 4)),
        PixelFormat::Rgb => Some(([0, 1, 2], 3)),
        PixelFormat::Bgr => Some(([2, 1, 0], 3)),
        PixelFormat::I420 | PixelFormat::Nv12 | PixelFormat::Y444 => None,
    }
}

/// For YUV formats: how many frame pixels one chroma sample covers in each
/// direction, and where Cb and Cr are (plane, byte offset, bytes between samples).
fn chroma(format: PixelFormat) -> (usize, [(usize, usize, usize); 2]) {
    match format {
        PixelFormat::I420 => (2, [(1, 0, 1), (2, 0, 1)]),
        PixelFormat::Nv12 => (2, [(1, 0, 2), (1, 1, 2)]),
        PixelFormat::Y444 => (1, [(1, 0, 1), (2, 0, 1)]),
        _ => panic!("{format:?} is not YUV"),
    }
}

/// Cb and Cr of frame pixel (x, y) of a YUV frame.
pub fn chroma_at(format: PixelFormat, planes: &[Plane; 3], x: usize, y: usize) -> (u8, u8) {
    let (sub, places) = chroma(format);
    let at = |(plane, offset, step): (usize, usize, usize)| {
        let p = &planes[plane];
        p.data[(y / sub) * p.stride + (x / sub) * step + offset]
    };
    (at(places[0]), at(places[1]))
}

#[allow(clippy::too_many_arguments)]
fn resample_channel(
    plane: &Plane,
    offset: usize,
    step: usize,
    x0: usize,
    y0: usize,
    wx: &AreaWeights,
    wy: &AreaWeights,
    out: &mut [f32],
) {
    let res_x = wx.start.len();
    let row_first = wy.start[0];
    let row_last = wy.start.last().unwrap() + wy.weights.last().unwrap().len();
    let mut rows = vec![0f32; (row_last - row_first) * res_x];
    for (r, row) in rows.chunks_exact_mut(res_x).enumerate() {
        let base = (y0 + row_first + r) * plane.stride + offset;
        for (o, (s, w)) in row.iter_mut().zip(wx.start.iter().zip(&wx.weights)) {
            let mut acc = 0.0;
            for (k, wk) in w.iter().enumerate() {
                acc += wk * plane.data[base + (x0 + s + k) * step] as f32;
            }
            *o = acc;
        }
    }
    for (oy, (s, w)) in wy.start.iter().zip(&wy.weights).enumerate() {
        let dst = &mut out[oy * res_x..(oy + 1) * res_x];
        dst.fill(0.0);
        for (k, wk) in w.iter().enumerate() {
            let src = &rows[(s + k - row_first) * res_x..(s + k - row_first + 1) * res_x];
            for (d, v) in dst.iter_mut().zip(src) {
                *d += wk * v;
            }
        }
    }
}

pub fn sample_crop(frame: &Frame, crop: Crop, res: usize) -> Vec<f32> {
    let n = res * res;
    let mut out = vec![0f32; 3 * n];
    let w = AreaWeights::new(crop.size, res);
    match packed(frame.format) {
        Some((offsets, bpp)) => {
            for (c, &off) in offsets.iter().enumerate() {
                let out = &mut out[c * n..(c + 1) * n];
                resample_channel(&frame.planes[0], off, bpp, crop.x, crop.y, &w, &w, out);
            }
            out.iter_mut().for_each(|v| *v /= 255.0);
        }
        None => {
            let (sub, places) = chroma(frame.format);
            let wc = AreaWeights::new(crop.size / sub, res);
            let mut yuv = vec![0f32; 3 * n];
            let (x, y) = (crop.x, crop.y);
            resample_channel(&frame.planes[0], 0, 1, x, y, &w, &w, &mut yuv[..n]);
            let (cx, cy) = (crop.x / sub, crop.y / sub);
            for (k, (plane, offset, step)) in places.into_iter().enumerate() {
                let out = &mut yuv[(k + 1) * n..(k + 2) * n];
                resample_channel(&frame.planes[plane], offset, step, cx, cy, &wc, &wc, out);
            }
            for i in 0..n {
                let rgb = frame.matrix.to_rgb(yuv[i], yuv[n + i], yuv[2 * n + i]);
                for c in 0..3 {
                    out[c * n + i] = rgb[c];
                }
            }
        }
    }
    out
}

/// The paste: every byte of every plane, each sample of the field
/// interpolated on its own.
pub fn apply(change: &LightingChange, frame: &mut FrameMut, crop: Crop, feather: usize) {
    let (width, height) = (frame.width, frame.height);
    let field = GainField::new(
        change,
        crop,
        feather,
        1.0,
        frame.format,
        frame.matrix,
        (width, height),
    );
    match packed(frame.format) {
        Some((offsets, bpp)) => {
            let (data, stride) = (&mut *frame.planes[0].0, frame.planes[0].1);
            for (c, offset) in offsets.into_iter().enumerate() {
                apply_channel(&field, (data, stride, offset, bpp), (width, height), c, 1);
            }
        }
        None => apply_yuv(&field, frame),
    }
}

/// The paste on a YUV frame: first every chroma sample's change, from the
/// frame as it is (its pixels' mean luma, its Cb and Cr); then the new Cb and
/// Cr, rounded; then every luma byte, with its chroma sample's term, dithered.
fn apply_yuv(field: &GainField, frame: &mut FrameMut) {
    let (width, height) = (frame.width, frame.height);
    let (sub, places) = chroma(frame.format);
    let (cw, ch) = (width.div_ceil(sub), height.div_ceil(sub));
    let (taps_x, taps_y) = (field.taps(cw, sub, 0), field.taps(ch, sub, 1));
    let mut changes = Vec::with_capacity(cw * ch);
    for cy in 0..ch {
        for cx in 0..cw {
            let (luma, stride) = (&frame.planes[0].0, frame.planes[0].1);
            let (mut sum, mut count) = (0u16, 0);
            for y in sub * cy..(sub * cy + sub).min(height) {
                for x in sub * cx..(sub * cx + sub).min(width) {
                    sum += u16::from(luma[y * stride + x]);
                    count += 1;
                }
            }
            let byte = |(plane, offset, step): (usize, usize, usize)| {
                let (data, stride) = (&frame.planes[plane].0, frame.planes[plane].1);
                data[cy * stride + cx * step + offset]
            };
            let chroma = (byte(places[0]), byte(places[1]));
            changes.push(field.chroma_at(taps_x[cx], taps_y[cy], (sum, count), chroma));
        }
    }
    for (k, (plane, offset, step)) in places.into_iter().enumerate() {
        let (data, stride) = (&mut *frame.planes[plane].0, frame.planes[plane].1);
        for cy in 0..ch {
            for cx in 0..cw {
                let value = changes[cy * cw + cx][k + 1];
                data[cy * stride + cx * step + offset] = value.round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    let (taps_x, taps_y) = (field.taps(width, 1, 0), field.taps(height, 1, 1));
    let (data, stride) = (&mut *frame.planes[0].0, frame.planes[0].1);
    for (y, &ty) in taps_y.iter().enumerate() {
        for (x, &tx) in taps_x.iter().enumerate() {
            let term = changes[(y / sub) * cw + x / sub][0];
            let extra = if field.dithers_at(x as f32 + 0.5, y as f32 + 0.5) {
                term + dither(x, y)
            } else {
                term
            };
            let value = field.luma_at(data[y * stride + x], tx, ty, extra);
            data[y * stride + x] = value.round().clamp(0.0, 255.0) as u8;
        }
    }
}

/// Applies RGB channel `channel` of `field` to the samples of one plane (its
/// bytes, stride, the channel's byte offset and bytes between samples), a
/// plane of `width` × `height` samples each `subsample` frame pixels wide.
fn apply_channel(
    field: &GainField,
    (data, stride, offset, step): (&mut [u8], usize, usize, usize),
    (width, height): (usize, usize),
    channel: usize,
    subsample: usize,
) {
    let (taps_x, taps_y) = (
        field.taps(width, subsample, 0),
        field.taps(height, subsample, 1),
    );
    for (y, &ty) in taps_y.iter().enumerate() {
        for (x, &tx) in taps_x.iter().enumerate() {
            let at = y * stride + x * step + offset;
            let frame = |v: usize| (v as f32 + 0.5) * subsample as f32;
            let dithers = field.dithers_at(frame(x), frame(y));
            let value = field.at(
                channel,
                data[at],
                tx,
                ty,
                if dithers { dither(x, y) } else { 0.0 },
            );
            data[at] = value.round().clamp(0.0, 255.0) as u8;
        }
    }
}
