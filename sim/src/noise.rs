//! Hash-based value noise for procedural textures.

use crate::rng::{hash, unit};

fn lattice(seed: u64, x: i32, y: i32) -> f32 {
    unit(hash(seed, &[x as u32 as u64, y as u32 as u64]))
}

fn fade(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

/// Smooth value noise in [0, 1] with unit lattice spacing.
pub fn value2(seed: u64, x: f32, y: f32) -> f32 {
    let (xf, yf) = (x.floor(), y.floor());
    let (xi, yi) = (xf as i32, yf as i32);
    let (tx, ty) = (fade(x - xf), fade(y - yf));
    let a = lattice(seed, xi, yi);
    let b = lattice(seed, xi + 1, yi);
    let c = lattice(seed, xi, yi + 1);
    let d = lattice(seed, xi + 1, yi + 1);
    let top = a + (b - a) * tx;
    let bottom = c + (d - c) * tx;
    top + (bottom - top) * ty
}

/// Fractal sum of `octaves` octaves, centred on zero, amplitude about ±0.5.
pub fn fbm2(seed: u64, x: f32, y: f32, octaves: u32) -> f32 {
    let mut sum = 0.0;
    let mut amp = 0.5;
    let mut freq = 1.0;
    let mut norm = 0.0;
    for o in 0..octaves {
        sum += amp * (value2(seed.wrapping_add(o as u64 * 7919), x * freq, y * freq) - 0.5);
        norm += amp;
        amp *= 0.5;
        freq *= 2.03;
    }
    sum / norm
}
