//! What the element's paste leaves with a perfect network: each frame's
//! lighting change taken from the exact truth's own crop in place of the
//! network's output, and pasted as the element pastes it.
//!
//! The element's error against the simulator's truth is the network's and the
//! paste's together. Fed the truth's crop, the network's part is gone: what is
//! left is what the paste itself cannot carry (a change smoother than the
//! truth's, faded beyond head and shoulders, bounded where the input is dark).
//! A target whose paste alone ends near the error aimed for needs a better
//! paste, not a better network.

use deskstage::monitor::RgbImage;
use gstlsydrelight::frame::{Crop, FacePlace, Frame, LightingChange, sample_crop};

use crate::footage::{Relit, packed, unpacked};
use crate::quality::Region;

/// Each frame of `input` with the lighting change from its crop to the same
/// crop of `truth` (both resampled to the network's resolution `res`), pasted
/// where, how faded and how strongly the element says it relit that frame
/// (`relit`, from [`crate::footage::relight`]). A frame the element relit
/// nothing in passes as it is, as the element passes it.
pub fn truth_pasted(
    input: &[RgbImage],
    truth: &[RgbImage],
    relit: &[Option<Relit>],
    res: usize,
) -> Result<Vec<RgbImage>, String> {
    if input.len() != truth.len() || input.len() != relit.len() {
        return Err(format!(
            "{} input frames, {} truth frames and {} relit frames: give one of each per frame",
            input.len(),
            truth.len(),
            relit.len()
        ));
    }
    input
        .iter()
        .zip(truth)
        .zip(relit)
        .map(|((input, truth), relit)| {
            let Some(relit) = relit else {
                return Ok(input.clone());
            };
            let (strength, feather) = relit.shown.ok_or(
                "the element's face region came without its lsydrelight parameters \
                 (an element after it dropped them)",
            )?;
            let Region { x, y, size } = relit.region;
            let crop = Crop { x, y, size };
            let crop_of = |img: &RgbImage| {
                sample_crop(
                    &Frame::packed_rgb(&img.data, img.width, img.height),
                    crop,
                    res,
                )
            };
            let change = LightingChange::new(
                &crop_of(input),
                &crop_of(truth),
                res,
                face_place(relit.face, relit.region),
            );
            let mut out = packed(input);
            change.apply_faded(&mut out.frame_mut(), crop, feather, strength);
            Ok(unpacked(out))
        })
        .collect()
}

/// Where `face` (one face height square about its centre) sits in the square
/// `crop`, in fractions of the crop's side: `gstlsydrelight::face::face_place`
/// read back from the element's meta, which gives the face, not the rule's
/// square it was made from.
fn face_place(face: Region, crop: Region) -> FacePlace {
    let side = crop.size as f32;
    let centre = |at: usize, from: usize| (at as f32 + face.size as f32 / 2.0 - from as f32) / side;
    FacePlace {
        centre: [centre(face.x, crop.x), centre(face.y, crop.y)],
        height: face.size as f32 / side,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(width: usize, height: usize, level: u8) -> RgbImage {
        RgbImage {
            width,
            height,
            data: vec![level; width * height * 3],
        }
    }

    fn relit_square(size: usize) -> Option<Relit> {
        let region = Region { x: 0, y: 0, size };
        Some(Relit {
            region,
            face: Region::face_within(region),
            shown: Some((1.0, size / 4)),
        })
    }

    #[test]
    fn the_truths_own_change_is_pasted_where_the_element_relit() {
        // A flat grey face whose truth is twice as bright: the paste of the
        // truth's change brings the middle of the relit square to the truth,
        // within the few levels the paste's smoothing of the gain leaves.
        let (input, truth) = (flat(64, 64, 60), flat(64, 64, 120));
        let out = truth_pasted(
            std::slice::from_ref(&input),
            &[truth],
            &[relit_square(64)],
            32,
        )
        .unwrap();
        let middle = (32 * 64 + 32) * 3;
        assert!(
            (out[0].data[middle] as i32 - 120).abs() <= 5,
            "{}",
            out[0].data[middle]
        );
        // Where the element relit nothing, the frame passes.
        let passed = truth_pasted(
            std::slice::from_ref(&input),
            &[flat(64, 64, 120)],
            &[None],
            32,
        )
        .unwrap();
        assert_eq!(passed[0].data, input.data);
    }

    #[test]
    fn frames_that_do_not_pair_are_refused() {
        let frame = flat(8, 8, 60);
        let err = truth_pasted(std::slice::from_ref(&frame), &[], &[None], 32).unwrap_err();
        assert!(err.contains("1 input frames, 0 truth frames"), "{err}");
    }

    #[test]
    fn the_face_is_placed_in_fractions_of_the_crop() {
        let place = face_place(
            Region {
                x: 140,
                y: 120,
                size: 40,
            },
            Region {
                x: 100,
                y: 100,
                size: 120,
            },
        );
        assert_eq!(place.centre, [0.5, 1.0 / 3.0]);
        assert_eq!(place.height, 1.0 / 3.0);
    }
}
