//! Image error between a displayed frame and its reference, and the pictures that show it.
//!
//! Errors are kept as mean squared errors (0-255 scale, over the RGB channels) so they can be
//! averaged over pixels and time before anything is converted to dB. Object pixels are those
//! where either image shows a measured object, as the renderer's object mask says: sky and
//! terrain, shared by both images, do not dilute the figure.

use std::path::Path;

use anyhow::Context;
use fixedbitset::FixedBitSet;
use serde::Serialize;

use crate::render::{Image, RenderError, Renderer};

/// The PSNR of identical images: kept out of means (means are taken over MSE).
pub const PSNR_CAP_DB: f64 = 99.0;

/// A frame as displayed: its colours and which pixels show a measured object, packed to
/// RGB and a bit per pixel. A bench keeps a shot of every sample instant, the run's and its
/// reference's, until it scores them: RGBA and a byte of mask took 5 bytes a pixel, this
/// takes 3.125.
#[derive(Debug, Clone)]
pub struct Shot {
    width: u32,
    height: u32,
    /// Three bytes a pixel, rows top first.
    rgb: Vec<u8>,
    /// Per pixel, rows top first: a measured object was drawn there.
    mask: FixedBitSet,
}

impl Shot {
    /// Packs a frame and its object mask (a flag per pixel, rows top first).
    pub fn new(image: &Image, mask: &[bool]) -> Shot {
        let pixels = image.width as usize * image.height as usize;
        assert_eq!(mask.len(), pixels, "the mask is not the image's size");
        let rgb = image
            .rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        let mut bits = FixedBitSet::with_capacity(pixels);
        for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
            bits.insert(i);
        }
        Shot {
            width: image.width,
            height: image.height,
            rgb,
            mask: bits,
        }
    }

    /// The frame `renderer` drew last and its object mask.
    pub fn read(renderer: &Renderer) -> Result<Shot, RenderError> {
        Ok(Shot::new(
            &renderer.read_frame()?,
            &renderer.read_object_mask()?,
        ))
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// How many pixels: the indices `rgb` and `is_object` take are `0..pixels()`.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The colour of pixel `i` (rows top first).
    pub fn rgb(&self, i: usize) -> [u8; 3] {
        let p = &self.rgb[i * 3..i * 3 + 3];
        [p[0], p[1], p[2]]
    }

    /// Whether pixel `i` (rows top first) shows a measured object.
    pub fn is_object(&self, i: usize) -> bool {
        self.mask.contains(i)
    }

    /// How many pixels show a measured object.
    pub fn object_pixels(&self) -> usize {
        self.mask.count_ones(..)
    }

    /// The colours as an opaque image, for pictures.
    pub fn image(&self) -> Image {
        Image {
            width: self.width,
            height: self.height,
            rgba: self
                .rgb
                .chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect(),
        }
    }
}

/// A shot with its colours lz4-compressed (the crate `lz4_flex`: fast both ways, and a
/// rendered frame's runs of sky, terrain and flat shading shrink about twelve times). A run
/// keeps one for every sample instant until it is over and its references can be drawn.
#[derive(Debug, Clone)]
pub struct PackedShot {
    width: u32,
    height: u32,
    /// The RGB bytes as an lz4 block, their length first.
    rgb: Vec<u8>,
    mask: FixedBitSet,
}

impl PackedShot {
    /// Compresses `shot`'s colours.
    pub fn pack(shot: Shot) -> PackedShot {
        PackedShot {
            width: shot.width,
            height: shot.height,
            rgb: lz4_flex::block::compress_prepend_size(&shot.rgb),
            mask: shot.mask,
        }
    }

    /// The shot as it was packed.
    pub fn unpack(&self) -> Shot {
        let rgb = lz4_flex::block::decompress_size_prepended(&self.rgb)
            .expect("a block lz4_flex compressed itself decompresses");
        Shot {
            width: self.width,
            height: self.height,
            rgb,
            mask: self.mask.clone(),
        }
    }

    /// Bytes held for the colours and the mask.
    pub fn bytes(&self) -> usize {
        self.rgb.len() + std::mem::size_of_val(self.mask.as_slice())
    }
}

/// How far a frame is from its reference.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ImageError {
    /// Mean squared difference over every pixel and RGB channel, 0-255 scale.
    pub mse: f64,
    /// The same over object pixels only (0 when there are none).
    pub object_mse: f64,
    /// The part of `object_mse` from silhouettes: pixels where only one of the two images
    /// shows an object (the rest is interiors: colour, lighting, occlusion between objects).
    pub silhouette_mse: f64,
    /// Pixels where either image shows an object.
    pub object_pixels: u64,
    /// Share of all pixels where some channel differs by more than the threshold.
    pub differing_share: f64,
    /// Mean FLIP error over object pixels (0 identical, 1 most different); `None` when not
    /// computed or when there are no object pixels.
    pub object_flip: Option<f64>,
}

impl ImageError {
    /// Whole-frame PSNR of this one comparison, dB.
    pub fn psnr_db(&self) -> f64 {
        psnr_db(self.mse)
    }
}

/// PSNR for a mean squared error on the 0-255 scale, capped at [`PSNR_CAP_DB`].
pub fn psnr_db(mse: f64) -> f64 {
    if mse > 0.0 {
        (10.0 * (255.0f64 * 255.0 / mse).log10()).min(PSNR_CAP_DB)
    } else {
        PSNR_CAP_DB
    }
}

/// Compares `shot` with `reference` (same size): whole-frame and object-pixel MSE, and the
/// share of pixels off by more than `threshold`. FLIP is left to [`object_flip`] (slow).
pub fn compare(reference: &Shot, shot: &Shot, threshold: u8) -> ImageError {
    assert_eq!(
        reference.size(),
        shot.size(),
        "compared images differ in size"
    );
    let (mut squared, mut object_squared, mut silhouette_squared) = (0u64, 0u64, 0u64);
    let (mut differing, mut object_pixels) = (0u64, 0u64);
    let pairs = reference.rgb.chunks_exact(3).zip(shot.rgb.chunks_exact(3));
    for (i, (pa, pb)) in pairs.enumerate() {
        let mut pixel = 0u64;
        let mut largest = 0u8;
        for channel in 0..3 {
            let d = pa[channel].abs_diff(pb[channel]);
            pixel += d as u64 * d as u64;
            largest = largest.max(d);
        }
        squared += pixel;
        differing += (largest > threshold) as u64;
        let (ma, mb) = (reference.is_object(i), shot.is_object(i));
        if ma || mb {
            object_squared += pixel;
            object_pixels += 1;
        }
        if ma != mb {
            silhouette_squared += pixel;
        }
    }
    let pixels = (reference.pixels() as u64).max(1);
    ImageError {
        mse: squared as f64 / (pixels * 3) as f64,
        object_mse: object_squared as f64 / (object_pixels.max(1) * 3) as f64,
        silhouette_mse: silhouette_squared as f64 / (object_pixels.max(1) * 3) as f64,
        object_pixels,
        differing_share: differing as f64 / pixels as f64,
        object_flip: None,
    }
}

/// Mean FLIP error (NVIDIA's perceptual difference, crate `nv-flip`) over the pixels where
/// either shot shows an object; `None` when there are none. FLIP is computed on the
/// bounding box of those pixels widened by a margin (its filters reach a few pixels), which
/// leaves the figure unchanged and saves most of the time on small objects.
pub fn object_flip(reference: &Shot, shot: &Shot) -> Option<f64> {
    const MARGIN: usize = 16;
    let (w, h) = (reference.width as usize, reference.height as usize);
    let union = |i: usize| reference.is_object(i) || shot.is_object(i);
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for i in (0..w * h).filter(|&i| union(i)) {
        let (x, y) = (i % w, i / w);
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    if x0 == usize::MAX {
        return None;
    }
    let (x0, y0) = (x0.saturating_sub(MARGIN), y0.saturating_sub(MARGIN));
    let (x1, y1) = ((x1 + MARGIN).min(w - 1), (y1 + MARGIN).min(h - 1));
    let (cw, ch) = (x1 - x0 + 1, y1 - y0 + 1);
    let crop = |shot: &Shot| {
        let mut rgb = Vec::with_capacity(cw * ch * 3);
        for y in y0..=y1 {
            rgb.extend_from_slice(&shot.rgb[(y * w + x0) * 3..(y * w + x1 + 1) * 3]);
        }
        nv_flip::FlipImageRgb8::with_data(cw as u32, ch as u32, &rgb)
    };
    let map = nv_flip::flip(
        crop(reference),
        crop(shot),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    )
    .to_vec();
    let (mut sum, mut count) = (0.0f64, 0u64);
    for y in y0..=y1 {
        for x in x0..=x1 {
            if union(y * w + x) {
                sum += map[(y - y0) * cw + (x - x0)] as f64;
                count += 1;
            }
        }
    }
    Some(sum / count as f64)
}

/// Popping: how far the change between two consecutive displayed shots is from the change
/// between their references, as a mean squared error over the pixels where any of the four
/// shows an object. Zero when the frames change exactly as the references do; a board or a
/// level of detail that snaps to another, or a frame held too long, makes it grow.
pub fn temporal_mse(previous: (&Shot, &Shot), current: (&Shot, &Shot)) -> f64 {
    let ((reference_0, shot_0), (reference_1, shot_1)) = (previous, current);
    let mut squared = 0i64;
    let mut pixels = 0u64;
    let shots = [reference_0, shot_0, reference_1, shot_1];
    for i in 0..reference_1.pixels() {
        if !shots.iter().any(|s| s.is_object(i)) {
            continue;
        }
        pixels += 1;
        for c in 0..3 {
            let at = i * 3 + c;
            let shown = shot_1.rgb[at] as i64 - shot_0.rgb[at] as i64;
            let wanted = reference_1.rgb[at] as i64 - reference_0.rgb[at] as i64;
            squared += (shown - wanted) * (shown - wanted);
        }
    }
    squared as f64 / (pixels.max(1) * 3) as f64
}

/// Reference, frame, and their difference (amplified 4x) side by side.
pub fn side_by_side(reference: &Image, image: &Image) -> Image {
    let (w, h) = (reference.width as usize, reference.height as usize);
    let mut rgba = vec![0u8; w * 3 * h * 4];
    for row in 0..h {
        for column in 0..w {
            let at = (row * w + column) * 4;
            let a = &reference.rgba[at..at + 4];
            let b = &image.rgba[at..at + 4];
            let difference = [0, 1, 2].map(|c| (a[c].abs_diff(b[c]) as u32 * 4).min(255) as u8);
            for (panel, pixel) in [[a[0], a[1], a[2]], [b[0], b[1], b[2]], difference]
                .iter()
                .enumerate()
            {
                let to = (row * w * 3 + panel * w + column) * 4;
                rgba[to..to + 3].copy_from_slice(pixel);
                rgba[to + 3] = 255;
            }
        }
    }
    Image {
        width: (w * 3) as u32,
        height: h as u32,
        rgba,
    }
}

/// Images of the same height placed left to right.
pub fn row_of(images: &[&Image]) -> Image {
    let height = images.iter().map(|i| i.height).max().unwrap_or(0);
    let width: u32 = images.iter().map(|i| i.width).sum();
    let mut rgba = vec![0u8; (width * height * 4) as usize];
    let mut left = 0usize;
    for image in images {
        for row in 0..image.height as usize {
            let from = row * image.width as usize * 4;
            let to = (row * width as usize + left) * 4;
            rgba[to..to + image.width as usize * 4]
                .copy_from_slice(&image.rgba[from..from + image.width as usize * 4]);
        }
        left += image.width as usize;
    }
    Image {
        width,
        height,
        rgba,
    }
}

/// Writes an opaque image as PNG.
pub fn write_png(image: &Image, path: &Path) -> anyhow::Result<()> {
    let size = tiny_skia::IntSize::from_wh(image.width, image.height).context("empty image")?;
    let mut rgba = image.rgba.clone();
    // Opaque, so premultiplied equals straight alpha.
    rgba.chunks_exact_mut(4).for_each(|p| p[3] = 255);
    let pixmap = tiny_skia::Pixmap::from_vec(rgba, size).context("image size mismatch")?;
    pixmap
        .save_png(path)
        .with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shot(width: u32, height: u32, color: impl Fn(usize) -> [u8; 3], mask: &[usize]) -> Shot {
        let pixels = (width * height) as usize;
        let image = Image {
            width,
            height,
            rgba: (0..pixels)
                .flat_map(|i| {
                    let [r, g, b] = color(i);
                    [r, g, b, 255]
                })
                .collect(),
        };
        let mask: Vec<bool> = (0..pixels).map(|i| mask.contains(&i)).collect();
        Shot::new(&image, &mask)
    }

    #[test]
    fn a_packed_shot_keeps_every_colour_and_mask_flag() {
        // 70 pixels: the mask's bits run past one 64-bit block. Alpha is not kept (frames
        // are opaque): the image comes back with 255.
        let (width, height) = (10, 7);
        let rgba: Vec<u8> = (0..70u32)
            .flat_map(|i| [i as u8, (i * 3) as u8, 255 - i as u8, (i % 5) as u8])
            .collect();
        let mask: Vec<bool> = (0..70).map(|i| i % 3 == 0 || i == 68).collect();
        let image = Image {
            width,
            height,
            rgba: rgba.clone(),
        };
        let shot = Shot::new(&image, &mask);
        assert_eq!((shot.size(), shot.pixels()), ((10, 7), 70));
        for i in 0..70 {
            assert_eq!(shot.rgb(i), [rgba[i * 4], rgba[i * 4 + 1], rgba[i * 4 + 2]]);
            assert_eq!(shot.is_object(i), mask[i], "pixel {i}");
        }
        assert_eq!(shot.object_pixels(), 24 + 1);
        let back = shot.image();
        assert_eq!((back.width, back.height), (10, 7));
        for (i, p) in back.rgba.chunks_exact(4).enumerate() {
            assert_eq!(p, [rgba[i * 4], rgba[i * 4 + 1], rgba[i * 4 + 2], 255]);
        }
    }

    #[test]
    fn a_compressed_shot_unpacks_to_the_same_pixels_in_a_fraction_of_the_bytes() {
        // A frame-like picture: a flat sky over a shaded ground, an object in the middle
        // with a noisy texture that compresses badly.
        let (width, height) = (200, 150);
        let color = |i: usize| {
            let (x, y) = (i % 200, i / 200);
            if (80..120).contains(&x) && (50..100).contains(&y) {
                let noise = (i as u32).wrapping_mul(2_654_435_761) >> 24;
                [noise as u8, 90, 40]
            } else if y < 75 {
                [120, 160, 230]
            } else {
                [60, 100 + (y / 10) as u8, 50]
            }
        };
        let mask: Vec<usize> = (0..30_000)
            .filter(|i| (80..120).contains(&(i % 200)) && (50..100).contains(&(i / 200)))
            .collect();
        let original = shot(width, height, color, &mask);
        let packed = PackedShot::pack(original.clone());
        let unpacked = packed.unpack();
        assert_eq!(unpacked.size(), (200, 150));
        for i in 0..30_000 {
            assert_eq!(unpacked.rgb(i), color(i), "pixel {i}");
            assert_eq!(unpacked.is_object(i), mask.contains(&i), "pixel {i}");
        }
        // The 2,000 noisy pixels stay about 6 kB; the rest, 84 kB raw, nearly vanishes.
        let raw = 30_000 * 3;
        assert!(
            packed.bytes() < raw / 5,
            "{} of {raw} bytes",
            packed.bytes()
        );
    }

    #[test]
    #[should_panic(expected = "the mask is not the image's size")]
    fn a_mask_of_another_size_is_refused() {
        let image = Image {
            width: 2,
            height: 2,
            rgba: vec![0; 16],
        };
        Shot::new(&image, &[true; 3]);
    }

    #[test]
    fn object_error_counts_only_pixels_either_mask_covers() {
        // 10x10 grey; the frame has pixel 5 off by 30 in every channel and pixel 50 off by
        // 10 in red. Objects: pixel 5 in the reference, 7 in the frame.
        let reference = shot(10, 10, |_| [100; 3], &[5]);
        let frame = shot(
            10,
            10,
            |i| match i {
                5 => [130; 3],
                50 => [110, 100, 100],
                _ => [100; 3],
            },
            &[7],
        );
        let error = compare(&reference, &frame, 20);
        // Whole frame: (3*900 + 100) / 300 pixel-channels.
        assert!((error.mse - 2800.0 / 300.0).abs() < 1e-12, "{error:?}");
        // Object pixels 5 and 7: 3*900 / 6.
        assert_eq!(error.object_pixels, 2);
        assert!((error.object_mse - 450.0).abs() < 1e-12, "{error:?}");
        assert!((error.differing_share - 0.01).abs() < 1e-12);
        // PSNR from MSE: 10 log10(255^2 / 450) = 21.60 dB.
        assert!((psnr_db(error.object_mse) - 21.5977).abs() < 1e-3);
        assert_eq!(psnr_db(0.0), PSNR_CAP_DB);
    }

    #[test]
    fn flip_is_zero_for_equal_shots_and_grows_with_the_difference() {
        let reference = shot(64, 64, |i| [(i % 64 * 4) as u8, 80, 120], &[2080, 2081]);
        assert_eq!(object_flip(&reference, &reference), Some(0.0));
        let dim = shot(64, 64, |i| [(i % 64 * 4) as u8 / 2, 80, 120], &[2080]);
        let dark = shot(64, 64, |_| [0, 0, 0], &[2080]);
        let a = object_flip(&reference, &dim).unwrap();
        let b = object_flip(&reference, &dark).unwrap();
        assert!(0.0 < a && a < b && b <= 1.0, "{a} {b}");
        let empty = shot(64, 64, |_| [0; 3], &[]);
        assert_eq!(object_flip(&empty, &empty), None);
    }

    #[test]
    fn popping_is_the_change_the_reference_does_not_make() {
        let still = shot(4, 1, |_| [50; 3], &[0, 1, 2, 3]);
        let moved = shot(
            4,
            1,
            |i| if i == 0 { [90; 3] } else { [50; 3] },
            &[0, 1, 2, 3],
        );
        // The frames change as the references do: no popping.
        assert_eq!(temporal_mse((&still, &still), (&moved, &moved)), 0.0);
        // The frame holds still while the reference changes (a stale image): 40^2 on one
        // pixel of four.
        assert_eq!(temporal_mse((&still, &still), (&moved, &still)), 400.0);
        // The frame jumps while the reference holds still (a pop): the same.
        assert_eq!(temporal_mse((&still, &still), (&still, &moved)), 400.0);
    }
}
