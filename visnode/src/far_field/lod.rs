//! `--impostor lod`: what a user with one machine would do instead of reliefboards, a
//! discrete level-of-detail chain per object built with meshoptimizer ([`backend::LodChain`],
//! the same chain a worker renders boards from), chosen per frame by meshoptimizer's documented rule: the
//! coarsest level whose world-space error projects to at most `--lod-pixels` pixels.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use backend::LodChain;
use backend::simplify::{MAX_LEVELS, MIN_TRIANGLES, STUCK_SHARE};
use rayon::prelude::*;

use super::{DrawScene, FarField, Loading};
use crate::camera::View;
use crate::plan::{ObjectInfo, Plan};
use crate::render::{DrawItem, Renderer};

/// Bump when the chain built for the same object changes.
const CACHE_VERSION: u64 = 2;
const CACHE_MAGIC: &[u8; 8] = b"RBLOD001";

/// Where the chains of `objects` (those marked in `wanted`) are cached in `directory`: the
/// key hashes their geometry, so another scene or a changed one misses.
pub fn cache_path(directory: &Path, objects: &[scene::Object], wanted: &[bool]) -> PathBuf {
    let mut hasher = xxhash_rust::xxh3::Xxh3::new();
    hasher.update(&CACHE_VERSION.to_le_bytes());
    hasher.update(
        &[
            STUCK_SHARE.to_bits(),
            MIN_TRIANGLES as u64,
            MAX_LEVELS as u64,
        ]
        .map(u64::to_le_bytes)
        .concat(),
    );
    for (object, _) in objects.iter().zip(wanted).filter(|(_, w)| **w) {
        hasher.update(&(object.positions.len() as u64).to_le_bytes());
        hasher.update(bytemuck::cast_slice(&object.origin.to_array()));
        for position in &object.positions {
            hasher.update(bytemuck::cast_slice(&position.to_array()));
        }
        hasher.update(bytemuck::cast_slice(&object.triangles));
    }
    directory.join(format!("lod-{:032x}.bin", hasher.digest128()))
}

/// Reads cached chains, one per object; any problem (missing, truncated, another version)
/// is a miss. Indices are checked against the vertices when a chain is used
/// ([`LodChain::fits`]): a damaged file costs a rebuild, never a bad draw.
pub fn read_cache(path: &Path, objects: usize) -> Option<Vec<LodChain>> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .ok()?
        .read_to_end(&mut bytes)
        .ok()?;
    let mut rest = bytes.strip_prefix(CACHE_MAGIC)?;
    let mut take = |n: usize| -> Option<&[u8]> {
        let (head, tail) = (rest.get(..n)?, rest.get(n..)?);
        rest = tail;
        Some(head)
    };
    let mut chains = Vec::with_capacity(objects.min(1 << 20));
    for _ in 0..objects {
        let levels = u32::from_le_bytes(take(4)?.try_into().ok()?) as usize;
        let mut chain = LodChain {
            levels: Vec::new(),
            errors: vec![0.0],
        };
        for _ in 0..levels.min(MAX_LEVELS + 1) {
            let error = f64::from_le_bytes(take(8)?.try_into().ok()?);
            let count = u32::from_le_bytes(take(4)?.try_into().ok()?) as usize;
            let indices = take(count.checked_mul(12)?)?;
            if !(error.is_finite() && error >= *chain.errors.last()?) {
                return None;
            }
            chain.errors.push(error);
            chain.levels.push(
                indices
                    .chunks_exact(12)
                    .map(|t| {
                        let at =
                            |k: usize| u32::from_le_bytes(t[k * 4..k * 4 + 4].try_into().unwrap());
                        [at(0), at(1), at(2)]
                    })
                    .collect(),
            );
        }
        chains.push(chain);
    }
    rest.is_empty().then_some(chains)
}

/// Writes the chains atomically (a temporary file renamed into place).
pub fn write_cache(path: &Path, chains: &[LodChain]) -> std::io::Result<()> {
    if let Some(directory) = path.parent() {
        std::fs::create_dir_all(directory)?;
    }
    let temporary = path.with_extension(format!("tmp{}", std::process::id()));
    {
        let mut out = std::io::BufWriter::new(std::fs::File::create(&temporary)?);
        out.write_all(CACHE_MAGIC)?;
        for chain in chains {
            out.write_all(&(chain.levels.len() as u32).to_le_bytes())?;
            for (level, error) in chain.levels.iter().zip(&chain.errors[1..]) {
                out.write_all(&error.to_le_bytes())?;
                out.write_all(&(level.len() as u32).to_le_bytes())?;
                out.write_all(bytemuck::cast_slice(level))?;
            }
        }
        out.flush()?;
    }
    std::fs::rename(&temporary, path)
}

/// The coarsest level whose error `errors[level]` covers at most `max_pixels` pixels on screen
/// for an object whose bounding sphere (`radius`) has its centre `distance` from the eye:
/// meshoptimizer's rule, `e / max(d - r, tiny) * pixels_per_radian`, with
/// `pixels_per_radian = height / (2 tan(fov_y / 2))`. Level 0 when the eye is inside the
/// sphere.
pub fn choose_level(
    errors: &[f64],
    distance: f64,
    radius: f64,
    pixels_per_radian: f64,
    max_pixels: f64,
) -> usize {
    let d = distance - radius;
    if !(d > 0.0) {
        return 0;
    }
    errors
        .iter()
        .rposition(|&e| e / d * pixels_per_radian <= max_pixels)
        .unwrap_or(0)
}

/// Pixels of `error` for an object `distance` from the eye (its sphere `radius`): what
/// [`choose_level`] compares with the bound.
pub fn projected_pixels(error: f64, distance: f64, radius: f64, pixels_per_radian: f64) -> f64 {
    error / (distance - radius).max(1e-9) * pixels_per_radian
}

/// Level-of-detail chains for a set of objects: read from the cache or built at load, the
/// coarser levels uploaded as extra index buffers of each object's mesh, and the errors
/// kept for choosing a level per frame. The viewer holds one ([`crate::viewer::GeometryLod`])
/// for every object it draws as geometry beyond the near zone, whatever the far field: the
/// unsuitable ones (terrain, walls, pipes) and suitable ones without a valid board, so their
/// triangles shrink with distance too; with `--impostor lod` that is every far object.
pub struct Levels {
    /// Per object, its chain: read from the cache or built at load (the full mesh alone
    /// otherwise). The levels' index lists are dropped once on the GPU (and written to the
    /// cache); the errors stay for choosing levels.
    chains: Vec<LodChain>,
    /// Which objects get chains.
    wanted: Vec<bool>,
    /// Where the chains are cached, and whether any had to be built (so the cache is
    /// written again).
    cache: Option<PathBuf>,
    rebuilt: bool,
    /// Whether `chains` came from the cache (else they are placeholders to build).
    from_cache: bool,
    /// The level drawn is the coarsest whose error covers at most this many pixels.
    max_pixels: f64,
}

impl Levels {
    /// Chains for the `objects` marked in `wanted`, cached in `cache_dir` when given, drawn
    /// within `max_pixels` of error.
    pub fn new(
        cache_dir: Option<&Path>,
        objects: &[scene::Object],
        wanted: &[bool],
        max_pixels: f64,
    ) -> Levels {
        let cache = cache_dir.map(|dir| cache_path(dir, objects, wanted));
        let cached = cache
            .as_deref()
            .and_then(|path| read_cache(path, objects.len()));
        Levels {
            rebuilt: cached.is_none(),
            from_cache: cached.is_some(),
            chains: cached.unwrap_or_else(|| vec![LodChain::default(); objects.len()]),
            wanted: wanted.to_vec(),
            cache,
            max_pixels,
        }
    }

    /// Whether `object` gets a chain.
    pub fn wants(&self, object: usize) -> bool {
        self.wanted.get(object).copied().unwrap_or(false)
    }

    /// Builds (or takes from the cache) the chains of a batch of objects and uploads their
    /// coarser levels.
    pub fn load(&mut self, renderer: &Renderer, batch: Vec<Loading<'_>>) {
        let (chains, from_cache) = (&self.chains, self.from_cache);
        // Building is the slow part: in parallel; uploads in order. A cached chain is used
        // where it fits the object's vertices.
        let built: Vec<Option<LodChain>> = batch
            .par_iter()
            .map(|loading| {
                let fits = from_cache
                    && chains
                        .get(loading.id as usize)
                        .is_some_and(|chain| chain.fits(loading.object.vertices.len()));
                (!fits)
                    .then(|| LodChain::build(&loading.object.vertices, &loading.object.triangles))
            })
            .collect();
        for (loading, built) in batch.into_iter().zip(built) {
            let id = loading.id as usize;
            if id >= self.chains.len() {
                self.chains.resize(id + 1, LodChain::default());
            }
            if let Some(chain) = built {
                self.chains[id] = chain;
                self.rebuilt = true;
            }
            renderer.add_levels(loading.mesh, &self.chains[id].levels);
            if self.cache.is_none() {
                // Nothing to write them to: on the GPU is enough.
                self.chains[id].levels = Vec::new();
            }
        }
    }

    /// After the last batch: writes the cache when chains were built, and drops the index
    /// lists (they are on the GPU).
    pub fn loaded(&mut self) {
        if let Some(path) = self.cache.as_deref().filter(|_| self.rebuilt) {
            // A cache that cannot be written costs time next run, nothing else.
            if let Err(error) = write_cache(path, &self.chains) {
                eprintln!("levels of detail not cached: {}: {error}", path.display());
            }
        }
        for chain in &mut self.chains {
            chain.levels = Vec::new();
        }
    }

    /// The level drawn for `object` (its bounds in `info`) from `view`: the coarsest whose
    /// error covers at most the bound's pixels (0, the full mesh, without a chain).
    pub fn level(&self, object: u32, info: &ObjectInfo, view: &View) -> usize {
        choose_level(
            self.chains
                .get(object as usize)
                .map_or(&[][..], |c| &c.errors),
            (info.center - view.eye).length(),
            info.radius,
            view.pixels_per_radian,
            self.max_pixels,
        )
    }
}

/// The LOD far field: no boards, so every suitable object beyond the near zone is fallback,
/// drawn at the level the plan chose (the coarsest of its chain within `--lod-pixels`), or
/// whole when boards were wanted with `--whole-fallback`.
pub struct LodField {
    reason: String,
    fallback_levels: bool,
}

impl LodField {
    /// `--impostor lod`.
    pub fn chosen() -> LodField {
        LodField {
            reason: "--impostor lod: levels of detail, no workers".into(),
            fallback_levels: true,
        }
    }

    /// Boards were asked for but none can be made, for `reason`: every far object is drawn
    /// as a board's own fallback would draw it, so the unsuitable ones keep their levels
    /// (whole, a plant of 12 M triangles took 872 ms a frame where LOD took 90) and the
    /// suitable ones go through theirs when `fallback_levels`, else whole (`--whole-fallback`).
    pub fn instead_of_boards(reason: impl Into<String>, fallback_levels: bool) -> LodField {
        LodField {
            reason: reason.into(),
            fallback_levels,
        }
    }
}

impl FarField for LodField {
    fn no_boards_reason(&self) -> Option<&str> {
        Some(&self.reason)
    }

    fn fallback_through_levels(&self) -> bool {
        self.fallback_levels
    }

    fn draw<'a>(&'a self, scene: &DrawScene<'a>, plan: &Plan, items: &mut Vec<DrawItem<'a>>) {
        items.extend(scene.fallback_geometry(plan));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cache_returns_what_was_written_and_refuses_damage() {
        let chains = vec![
            LodChain::default(),
            LodChain {
                levels: vec![vec![[0, 1, 2], [2, 1, 3]], vec![[0, 1, 3]]],
                errors: vec![0.0, 0.25, 0.5],
            },
        ];
        let dir = std::env::temp_dir().join(format!("lod-cache-{}", std::process::id()));
        let path = dir.join("lod.bin");
        write_cache(&path, &chains).unwrap();
        let read = read_cache(&path, 2).unwrap();
        assert_eq!(read[1].levels, chains[1].levels);
        assert_eq!(read[1].errors, chains[1].errors);
        assert!(read[0].levels.is_empty());
        assert!(read[1].fits(4) && !read[1].fits(3));
        // Another object count, a truncated file and a forged count are misses.
        assert!(read_cache(&path, 3).is_none());
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 1]).unwrap();
        assert!(read_cache(&path, 2).is_none());
        let mut forged = bytes.clone();
        forged[8 + 4 + 4 + 8..8 + 4 + 4 + 8 + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        std::fs::write(&path, &forged).unwrap();
        assert!(read_cache(&path, 2).is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_chosen_level_is_the_coarsest_within_the_bound() {
        let errors = [0.0, 0.01, 0.02, 0.08, 0.5];
        // 1000 px per radian: at d = 100 (distance 101, radius 1) the errors are
        // 0, 0.1, 0.2, 0.8, 5 px.
        assert_eq!(choose_level(&errors, 101.0, 1.0, 1000.0, 1.0), 3);
        assert_eq!(choose_level(&errors, 101.0, 1.0, 1000.0, 0.15), 1);
        assert_eq!(choose_level(&errors, 101.0, 1.0, 1000.0, 0.05), 0);
        // Inside the sphere: the full mesh.
        assert_eq!(choose_level(&errors, 0.5, 1.0, 1000.0, 100.0), 0);
    }
}
