//! Request traces: what the visualization node records and the simulation replays.
//!
//! The on-disk form is JSON Lines, one [`TraceRecord`] per line:
//! `{"frame": 12, "object": 345, "weight": 120000, "time": 0.4}` (`time` in seconds is
//! optional; without it frames are 1/30 s apart).

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// One request of a trace.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TraceRecord {
    /// Position on the walk-through (frame number); records are grouped by it.
    pub frame: u64,
    /// The object requested.
    pub object: u32,
    /// Its weight (triangles).
    pub weight: f64,
    /// When, in seconds from the start.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<f64>,
}

/// A trace: records in frame order, and how many objects there are.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    /// The records, sorted by frame.
    pub records: Vec<TraceRecord>,
}

impl Trace {
    /// A trace from records in any order.
    pub fn new(mut records: Vec<TraceRecord>) -> Trace {
        records.sort_by_key(|r| r.frame);
        Trace { records }
    }

    /// Parses JSON Lines; blank lines are skipped. An error names the line.
    pub fn from_json_lines(text: &str) -> Result<Trace, String> {
        let mut records = Vec::new();
        for (index, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let record: TraceRecord =
                serde_json::from_str(line).map_err(|e| format!("line {}: {e}", index + 1))?;
            if !(record.weight >= 0.0 && record.weight.is_finite()) {
                return Err(format!(
                    "line {}: weight must be a finite non-negative number",
                    index + 1
                ));
            }
            if record.time.is_some_and(|t| !t.is_finite()) {
                return Err(format!("line {}: time must be finite", index + 1));
            }
            records.push(record);
        }
        Ok(Trace::new(records))
    }

    /// The trace as JSON Lines.
    pub fn to_json_lines(&self) -> String {
        self.records
            .iter()
            .map(|r| serde_json::to_string(r).unwrap_or_default() + "\n")
            .collect()
    }

    /// Number of objects the trace refers to (largest id + 1).
    pub fn object_count(&self) -> usize {
        self.records
            .iter()
            .map(|r| r.object as usize + 1)
            .max()
            .unwrap_or(0)
    }

    /// The records grouped by frame, in order, with each frame's time.
    pub fn positions(&self) -> Vec<(u64, f64, &[TraceRecord])> {
        let mut positions = Vec::new();
        let mut start = 0;
        while start < self.records.len() {
            let frame = self.records[start].frame;
            let end = start
                + self.records[start..]
                    .iter()
                    .take_while(|r| r.frame == frame)
                    .count();
            let group = &self.records[start..end];
            let time = group
                .iter()
                .find_map(|r| r.time)
                .unwrap_or(frame as f64 / 30.0);
            positions.push((frame, time, group));
            start = end;
        }
        positions
    }
}

/// The built-in synthetic walk-throughs.
pub const SYNTHETIC_TRACES: [&str; 3] = ["walk", "orbit", "bursts"];

/// A synthetic walk-through of `positions` frames over `objects` objects (weights from
/// 20,000 to 200,000 triangles, log-uniform), deterministic from `seed`:
///
/// - `walk`: a few requests at most positions (the camera creeps), bursts of hundreds where it
///   turns fast, like a person flying through a forest.
/// - `orbit`: a steady stream, every visible board ageing at the same pace.
/// - `bursts`: nothing most of the time, then very large bursts (teleports, big turns).
pub fn synthetic_trace(name: &str, positions: u64, objects: u32, seed: u64) -> Option<Trace> {
    if !SYNTHETIC_TRACES.contains(&name) || objects == 0 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let weights: Vec<f64> = (0..objects)
        .map(|_| 20_000.0 * 10f64.powf(rng.random_range(0.0..1.0)))
        .collect();
    let mut records = Vec::new();
    for frame in 0..positions {
        let count = match name {
            "walk" => {
                if rng.random_bool(0.02) {
                    rng.random_range(200..1500)
                } else {
                    rng.random_range(0..8)
                }
            }
            "orbit" => rng.random_range(40..120),
            _ => {
                if rng.random_bool(0.005) {
                    rng.random_range(1000..4000)
                } else {
                    rng.random_range(0..2)
                }
            }
        };
        // A burst asks for distinct objects: one request per object is pending at a time.
        let count = count.min(objects as usize);
        for object in rand::seq::index::sample(&mut rng, objects as usize, count) {
            records.push(TraceRecord {
                frame,
                object: object as u32,
                weight: weights[object],
                time: None,
            });
        }
    }
    Some(Trace::new(records))
}
