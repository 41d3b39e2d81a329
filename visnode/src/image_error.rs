//! Image error between a frame and its reference, and the pictures that show it.

use std::path::Path;

use anyhow::Context;
use serde::Serialize;

use crate::render::Image;

/// How far a frame is from its reference.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ImageError {
    /// Root mean square difference over the RGB channels, 0-255 scale.
    pub rmse: f64,
    /// Peak signal-to-noise ratio, dB (`20 log10(255 / rmse)`; 99 for identical images).
    pub psnr_db: f64,
    /// Share of pixels where some channel differs by more than the threshold.
    pub differing_share: f64,
}

/// Compares `image` with `reference` (same size).
pub fn compare(reference: &Image, image: &Image, threshold: u8) -> ImageError {
    assert_eq!(
        (reference.width, reference.height),
        (image.width, image.height),
        "compared images differ in size"
    );
    let mut squared = 0u64;
    let mut differing = 0u64;
    for (a, b) in reference
        .rgba
        .chunks_exact(4)
        .zip(image.rgba.chunks_exact(4))
    {
        let mut largest = 0u8;
        for channel in 0..3 {
            let d = a[channel].abs_diff(b[channel]);
            squared += d as u64 * d as u64;
            largest = largest.max(d);
        }
        differing += (largest > threshold) as u64;
    }
    let pixels = (reference.width as u64 * reference.height as u64).max(1);
    let rmse = (squared as f64 / (pixels * 3) as f64).sqrt();
    ImageError {
        rmse,
        psnr_db: if rmse > 0.0 {
            (20.0 * (255.0 / rmse).log10()).min(99.0)
        } else {
            99.0
        },
        differing_share: differing as f64 / pixels as f64,
    }
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
