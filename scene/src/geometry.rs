use glam::DVec3;
use serde::{Deserialize, Serialize};

/// An axis-aligned bounding box in world space (`f64`). An empty box has `min > max`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// The smallest corner.
    pub min: DVec3,
    /// The largest corner.
    pub max: DVec3,
}

impl Aabb {
    /// The empty box: the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    /// The smallest box holding all `points`.
    pub fn from_points(points: impl IntoIterator<Item = DVec3>) -> Aabb {
        points.into_iter().fold(Aabb::EMPTY, |b, p| b.including(p))
    }

    /// Whether the box holds no point.
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// This box grown to hold `point`.
    pub fn including(self, point: DVec3) -> Aabb {
        Aabb {
            min: self.min.min(point),
            max: self.max.max(point),
        }
    }

    /// The smallest box holding both boxes.
    pub fn union(self, other: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// Side lengths (zero for an empty box).
    pub fn size(&self) -> DVec3 {
        if self.is_empty() {
            DVec3::ZERO
        } else {
            self.max - self.min
        }
    }

    /// The longest side: the clustering cost of Süß §4.5.1.
    pub fn longest_side(&self) -> f64 {
        self.size().max_element()
    }

    /// The length of the diagonal: the diameter of the bounding sphere used for reliefboards.
    pub fn diagonal(&self) -> f64 {
        self.size().length()
    }

    /// The centre.
    pub fn center(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }
}

/// The image axes `(right, up)` for looking along the unit vector `forward`, with world +Y
/// up, as a camera holds them: right-handed, `right × up = -forward`. Only looking exactly up
/// or down leaves up undefined; then +Z stands in. No earlier switch: the image would roll
/// by the heading as the direction crossed it, and f64 keeps the cross product exact up to
/// there. The one definition the camera, the window's controls and the workers' boards use
/// (a frame around an axis with no preferred up is glam's `any_orthonormal_pair`).
pub fn view_axes(forward: DVec3) -> (DVec3, DVec3) {
    let hint = if forward.cross(DVec3::Y).length_squared() < 1e-20 {
        DVec3::Z
    } else {
        DVec3::Y
    };
    let right = forward.cross(hint).normalize();
    (right, right.cross(forward))
}

#[cfg(test)]
mod view_axes_tests {
    use super::*;

    #[test]
    fn view_axes_are_orthonormal_right_handed_and_level() {
        for forward in [
            DVec3::new(0.3, -0.2, -1.0),
            DVec3::new(0.0, 1.0, 1e-6),
            DVec3::Y,
            DVec3::NEG_Y,
            DVec3::X,
        ] {
            let forward = forward.normalize();
            let (right, up) = view_axes(forward);
            assert!((right.length() - 1.0).abs() < 1e-12, "{forward}");
            assert!((up.length() - 1.0).abs() < 1e-12, "{forward}");
            assert!(right.dot(up).abs() < 1e-12 && right.dot(forward).abs() < 1e-12);
            assert!((right.cross(up) + forward).length() < 1e-12, "{forward}");
            if forward.y.abs() < 1.0 {
                // Level: no roll, right stays horizontal and up leans toward +Y.
                assert!(
                    right.y.abs() < 1e-12 && up.y > 0.0,
                    "{forward}: {right} {up}"
                );
            }
        }
    }
}
