//! The contact sheet: the simulator's person under a grid of held-out monitor
//! lights and poses, at the desk and then under the dome the light code stands
//! for, for people to look at (`deskstage sheet`).

use rayon::prelude::*;

use crate::content::{self, Clip};
use crate::dataset::{heldout_states, still_lights};
use crate::material::Look;
use crate::monitor::{CellLight, MonitorGeometry, RgbImage};
use crate::render::{Renderer, Scene, Sensor};
use crate::subject::{State, Subject};

/// Poses of the sheet shown at the desk, and of those the first shown again under the dome.
const DESK_POSES: usize = 4;
const DOME_POSES: usize = 2;

/// The person under a grid of monitor lights (columns) and poses (rows), for
/// people to look at: [`DESK_POSES`] rows lit from the desk's screen, then
/// [`DOME_POSES`] of them lit by the same pictures from the dome.
pub fn contact_sheet(subject_seed: u64, cell: usize) -> Result<RgbImage, String> {
    let scene = Scene::new(Subject::from_seed(subject_seed), cell, cell);
    let dome = Renderer::new(Scene {
        monitor: MonitorGeometry::dome(),
        ..scene.clone()
    })?;
    let r = Renderer::new(scene)?;
    let mut clips: Vec<Clip> = content::heldout_clips(subject_seed);
    clips.truncate(6);
    let (shown, cells) = still_lights(&r, &clips);
    let refs: Vec<&CellLight> = cells.iter().collect();
    let states: Vec<State> = heldout_states().into_iter().take(DESK_POSES).collect();
    let rows: Vec<(&Renderer, &State)> = (states.iter().map(|s| (&r, s)))
        .chain(states.iter().take(DOME_POSES).map(|s| (&dome, s)))
        .collect();
    let look = Look::default();
    // One extra row on top shows each column's monitor frame.
    let cols = refs.len();
    let mut sheet = RgbImage::new(cell * cols, cell * (rows.len() + 1));
    for (c, frame) in shown.iter().enumerate() {
        let thumb = resize_area(frame, 0, 0, frame.width, frame.height, cell, cell * 9 / 16);
        paste(&mut sheet, &thumb, c * cell, (cell - thumb.height) / 2);
    }
    let rendered: Vec<Vec<RgbImage>> = rows
        .par_iter()
        .map(|(r, s)| {
            let t = r.prepare(&look, s);
            r.render(&t, &refs)
                .iter()
                .map(|img| Sensor::default().clean(img))
                .collect()
        })
        .collect();
    for (row, imgs) in rendered.iter().enumerate() {
        for (c, img) in imgs.iter().enumerate() {
            paste(&mut sheet, img, c * cell, (row + 1) * cell);
        }
    }
    Ok(sheet)
}

fn paste(dst: &mut RgbImage, src: &RgbImage, x0: usize, y0: usize) {
    for y in 0..src.height {
        let d = ((y0 + y) * dst.width + x0) * 3;
        dst.data[d..d + src.width * 3]
            .copy_from_slice(&src.data[y * src.width * 3..(y + 1) * src.width * 3]);
    }
}

/// Area-weighted resampling of the region (x0, y0, w, h) of `src` to `out_w`×`out_h`.
pub fn resize_area(
    src: &RgbImage,
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
    out_w: usize,
    out_h: usize,
) -> RgbImage {
    let mut out = RgbImage::new(out_w, out_h);
    let sx = w as f32 / out_w as f32;
    let sy = h as f32 / out_h as f32;
    for oy in 0..out_h {
        let (ya, yb) = (oy as f32 * sy, (oy + 1) as f32 * sy);
        for ox in 0..out_w {
            let (xa, xb) = (ox as f32 * sx, (ox + 1) as f32 * sx);
            let mut acc = [0.0f32; 3];
            let mut wsum = 0.0;
            for y in ya.floor() as usize..(yb.ceil() as usize).min(h) {
                let wy = (yb.min(y as f32 + 1.0) - ya.max(y as f32)).max(0.0);
                for x in xa.floor() as usize..(xb.ceil() as usize).min(w) {
                    let wx = (xb.min(x as f32 + 1.0) - xa.max(x as f32)).max(0.0);
                    let p = src.pixel(x0 + x, y0 + y);
                    for c in 0..3 {
                        acc[c] += wx * wy * p[c] as f32;
                    }
                    wsum += wx * wy;
                }
            }
            let i = (oy * out_w + ox) * 3;
            for (o, a) in out.data[i..i + 3].iter_mut().zip(acc) {
                *o = (a / wsum).round() as u8;
            }
        }
    }
    out
}
