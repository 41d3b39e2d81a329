//! A picture of a prepared scene seen from above (like Süß's Figure 4.12): every triangle's
//! centre in its object's class colour, and the outline of every suitable object's box.

use std::path::Path;

use scene::{Aabb, ObjectClass, PreparedScene};
use tiny_skia::{Color, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};

/// Longest side of the picture in pixels.
const PICTURE_SIDE: u32 = 1024;

/// Colour of each class: suitable green, too large red, too simple blue.
fn class_color(class: ObjectClass) -> [u8; 3] {
    match class {
        ObjectClass::Suitable => [40, 170, 60],
        ObjectClass::TooLarge => [210, 50, 40],
        ObjectClass::TooSimple => [40, 90, 220],
    }
}

/// Writes the picture as PNG, looking down the y axis (x to the right, z down).
pub fn write_png(prepared: &PreparedScene, path: &Path) -> anyhow::Result<()> {
    let bounds = prepared
        .objects
        .iter()
        .fold(Aabb::EMPTY, |b, o| b.union(o.bounds()));
    let size = bounds.size();
    let extent = size.x.max(size.z).max(1e-12);
    let scale = (PICTURE_SIDE - 1) as f64 / extent;
    let (width, height) = (
        ((size.x * scale) as u32 + 1).max(16),
        ((size.z * scale) as u32 + 1).max(16),
    );
    let mut pixmap = Pixmap::new(width, height)
        .ok_or_else(|| anyhow::anyhow!("cannot allocate a {width}x{height} picture"))?;
    pixmap.fill(Color::WHITE);
    let to_pixel = |x: f64, z: f64| ((x - bounds.min.x) * scale, (z - bounds.min.z) * scale);

    // Too-large objects first, so the smaller ones stay visible on top of floors.
    let mut order: Vec<usize> = (0..prepared.objects.len()).collect();
    order.sort_by_key(|&i| prepared.classes[i] != ObjectClass::TooLarge);
    let data = pixmap.data_mut();
    for &index in &order {
        let object = &prepared.objects[index];
        let [r, g, b] = class_color(prepared.classes[index]);
        for triangle in &object.triangles {
            let centre = triangle
                .iter()
                .map(|&v| object.world_position(v))
                .sum::<glam::DVec3>()
                / 3.0;
            let (px, py) = to_pixel(centre.x, centre.z);
            let (px, py) = (px as u32, py as u32);
            if px < width && py < height {
                let at = 4 * (py * width + px) as usize;
                data[at..at + 4].copy_from_slice(&[r, g, b, 255]);
            }
        }
    }
    let mut paint = Paint::default();
    paint.set_color_rgba8(0, 60, 0, 160);
    paint.anti_alias = true;
    let stroke = Stroke {
        width: 1.0,
        ..Stroke::default()
    };
    for (object, class) in prepared.objects.iter().zip(&prepared.classes) {
        if *class != ObjectClass::Suitable {
            continue;
        }
        let b = object.bounds();
        let (x0, y0) = to_pixel(b.min.x, b.min.z);
        let (x1, y1) = to_pixel(b.max.x, b.max.z);
        if let Some(rect) = Rect::from_ltrb(
            x0 as f32,
            y0 as f32,
            (x1 as f32).max(x0 as f32 + 1.0),
            (y1 as f32).max(y0 as f32 + 1.0),
        ) {
            let path = PathBuilder::from_rect(rect);
            pixmap.stroke_path(&path, &paint, &stroke, Transform::identity(), None);
        }
    }
    pixmap.save_png(path)?;
    Ok(())
}
