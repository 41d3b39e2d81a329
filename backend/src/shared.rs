//! Workers in one process share one prepared copy of each object. The visualization node's
//! in-process workers hold replicas of the same objects, and a copy per replica would
//! multiply the scene's memory by the replica count. A table of weak references keyed by
//! object id and content hash keeps a prepared object alive exactly as long as some worker
//! holds it; other content under the same id (another scene in the same process) gets its
//! own copy. Workers in separate processes are unaffected.

use std::collections::HashMap;
use std::sync::{Arc, LazyLock, Mutex, PoisonError, Weak};

use xxhash_rust::xxh3::Xxh3;

use crate::PreparedObject;

/// The content hash of an object as it arrives in chunks: each field hashed on its own, so
/// the result does not depend on where the chunks were cut.
#[derive(Default, Clone)]
pub(crate) struct Digest {
    header: Xxh3,
    positions: Xxh3,
    colors: Xxh3,
    triangles: Xxh3,
    seams: Xxh3,
}

impl Digest {
    pub fn update(&mut self, chunk: &proto::ObjectChunk) {
        if !chunk.name.is_empty() || chunk.total_vertices > 0 {
            self.header.update(chunk.name.as_bytes());
            for value in [chunk.origin_x, chunk.origin_y, chunk.origin_z] {
                self.header.update(&value.to_le_bytes());
            }
            self.header.update(&chunk.total_vertices.to_le_bytes());
            self.header.update(&chunk.total_triangles.to_le_bytes());
        }
        self.positions.update(&chunk.positions);
        self.colors.update(&chunk.colors);
        self.triangles.update(&chunk.triangles);
        self.seams.update(&chunk.seams);
    }

    pub fn finish(&self) -> u64 {
        let mut all = Xxh3::new();
        for part in [
            &self.header,
            &self.positions,
            &self.colors,
            &self.triangles,
            &self.seams,
        ] {
            all.update(&part.digest().to_le_bytes());
        }
        all.digest()
    }
}

/// One prepared object, or the place where the first worker to need it is preparing it
/// (the others wait on the lock instead of preparing a copy of their own).
type Slot = Arc<Mutex<Weak<PreparedObject>>>;

static TABLE: LazyLock<Mutex<HashMap<(u32, u64), Slot>>> = LazyLock::new(Default::default);

/// The prepared object `id` with content `digest`: the copy another worker of this process
/// holds, or a new one from `prepare`.
pub(crate) fn prepared<E>(
    id: u32,
    digest: u64,
    prepare: impl FnOnce() -> Result<PreparedObject, E>,
) -> Result<Arc<PreparedObject>, E> {
    let slot = {
        let mut table = TABLE.lock().unwrap_or_else(PoisonError::into_inner);
        // Forget objects no worker holds any more (a slot being filled stays).
        table.retain(|_, slot| slot.try_lock().map_or(true, |weak| weak.strong_count() > 0));
        table.entry((id, digest)).or_default().clone()
    };
    let mut weak = slot.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(object) = weak.upgrade() {
        return Ok(object);
    }
    let object = Arc::new(prepare()?);
    *weak = Arc::downgrade(&object);
    Ok(object)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    fn cube(scale: f64) -> PreparedObject {
        let mut builder = scene::ObjectBuilder::new("cube");
        let v: Vec<u32> = (0..8)
            .map(|i| {
                let p = glam::DVec3::new((i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2) as f64);
                builder.vertex(p * scale, [200; 4])
            })
            .collect();
        for [a, b, c] in [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5]] {
            builder.triangle(v[a], v[b], v[c]);
        }
        PreparedObject::new(&builder.finish().0).unwrap()
    }

    #[test]
    fn workers_share_one_copy_until_none_holds_it() {
        let prepares = AtomicUsize::new(0);
        let make = |scale| {
            prepares.fetch_add(1, Ordering::SeqCst);
            Ok::<_, ()>(cube(scale))
        };
        let first = prepared(900_001, 7, || make(1.0)).unwrap();
        let second = prepared(900_001, 7, || make(1.0)).unwrap();
        assert!(Arc::ptr_eq(&first, &second));
        assert_eq!(prepares.load(Ordering::SeqCst), 1);
        // Other content under the same id is another object.
        let other = prepared(900_001, 8, || make(2.0)).unwrap();
        assert!(!Arc::ptr_eq(&first, &other));
        // Once no worker holds it, it is prepared again.
        drop((first, second));
        let again = prepared(900_001, 7, || make(1.0)).unwrap();
        assert_eq!(prepares.load(Ordering::SeqCst), 3);
        drop(again);
    }

    #[test]
    fn replicas_stored_at_the_same_time_are_prepared_once() {
        let prepares = AtomicUsize::new(0);
        let copies: Vec<Arc<PreparedObject>> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..4)
                .map(|_| {
                    scope.spawn(|| {
                        prepared(900_002, 1, || {
                            prepares.fetch_add(1, Ordering::SeqCst);
                            std::thread::sleep(std::time::Duration::from_millis(50));
                            Ok::<_, ()>(cube(1.0))
                        })
                        .unwrap()
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert_eq!(prepares.load(Ordering::SeqCst), 1);
        assert!(copies.iter().all(|c| Arc::ptr_eq(c, &copies[0])));
    }

    #[test]
    fn the_digest_ignores_where_chunks_are_cut() {
        let object = cube(1.0);
        let mut builder = scene::ObjectBuilder::new("cube");
        for v in &object.vertices {
            builder.vertex(v.position.as_dvec3() + object.origin, [200; 4]);
        }
        for &[a, b, c] in &object.triangles {
            builder.triangle(a, b, c);
        }
        let chunks = proto::object_to_chunks(3, &builder.finish().0);
        let digest = |chunks: &[proto::ObjectChunk]| {
            let mut d = Digest::default();
            chunks.iter().for_each(|c| d.update(c));
            d.finish()
        };
        // All in one chunk, and the same bytes cut elsewhere into two.
        let mut one = chunks[0].clone();
        for c in &chunks[1..] {
            one.positions.extend_from_slice(&c.positions);
            one.colors.extend_from_slice(&c.colors);
            one.triangles.extend_from_slice(&c.triangles);
        }
        let mut first = one.clone();
        let second = proto::ObjectChunk {
            object_id: 3,
            positions: first.positions.split_off(12),
            colors: first.colors.split_off(4),
            triangles: first.triangles.split_off(24),
            ..Default::default()
        };
        let whole = digest(&chunks);
        assert_eq!(digest(std::slice::from_ref(&one)), whole);
        assert_eq!(digest(&[first, second]), whole);
        // Another colour is another digest.
        let mut recoloured = one;
        recoloured.colors[0] ^= 1;
        assert_ne!(digest(&[recoloured]), whole);
    }
}
