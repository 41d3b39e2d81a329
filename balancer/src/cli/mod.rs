//! Flags and the `simulate` and `trace` subcommands.

mod plots;
mod scaling;

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use balancer::{
    Baseline, Collision, Config, Policy, SimulationConfig, SimulationResult, SpeedUse, Strategy,
    Trace, simulate, synthetic_trace,
};
use clap::{Args, Parser, Subcommand, ValueEnum};
use rayon::prelude::*;
use serde::Serialize;

/// Replays reliefboard request traces on simulated workers.
#[derive(Debug, Parser)]
#[command(name = "balancer", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Replay a trace for several worker counts, replica counts, strategies and seeds,
    /// against the baselines, and write CSV, JSON and PNG reports.
    Simulate(SimulateArgs),
    /// Write a synthetic walk-through as a JSON Lines trace.
    Trace(TraceArgs),
    /// Plot Süß chapter 4's scaling figures from `scripts/chapter4-scaling.sh`'s table.
    Scaling(ScalingArgs),
}

#[derive(Debug, Args)]
struct ScalingArgs {
    /// The table (`scaling.csv`: one row per worker count).
    #[arg(long)]
    csv: PathBuf,
    /// Where the PNGs go.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Debug, Args)]
#[group(required = true, multiple = false, id = "source")]
struct Source {
    /// A JSON Lines trace (as `visnode bench --record-trace` writes).
    #[arg(long)]
    trace: Option<PathBuf>,
    /// A built-in walk-through: walk, orbit or bursts.
    #[arg(long)]
    synthetic: Option<String>,
}

#[derive(Debug, Args)]
struct SimulateArgs {
    #[command(flatten)]
    source: Source,
    /// Positions of a synthetic walk-through.
    #[arg(long, default_value_t = 6000)]
    positions: u64,
    /// Objects of a synthetic walk-through.
    #[arg(long, default_value_t = 2000)]
    objects: u32,
    /// Worker counts.
    #[arg(long, value_delimiter = ',', default_values_t = [32, 80, 120])]
    nodes: Vec<usize>,
    /// Replica counts.
    #[arg(long, value_delimiter = ',', default_values_t = [1, 2, 3])]
    replicas: Vec<usize>,
    /// Picking strategies.
    #[arg(long, value_delimiter = ',', default_values = ["deterministic", "randomized"])]
    strategy: Vec<StrategyArg>,
    /// Seeds (placements and random choices) per configuration.
    #[arg(long, default_value_t = 10)]
    seeds: u64,
    /// Relative worker speeds, cycled over the workers: "1" for all equal, "1,1,1,0.25" for
    /// every fourth worker four times slower.
    #[arg(long, default_value = "1")]
    speeds: String,
    /// Triangles per second a speed-1 worker renders.
    #[arg(long, default_value_t = 20e6)]
    base_speed: f64,
    /// Count (c-collision) or weight (c-load-collision).
    #[arg(long, value_enum, default_value_t = CollisionArg::Load)]
    collision: CollisionArg,
    /// c at the start and after progress (Süß: 1 in chapter 4, 2 in chapter 5; the
    /// balancer's default, 8, was tuned on the synthetic orbit).
    #[arg(long, default_value_t = Config::default().c_start)]
    c_start: f64,
    /// Added to c after a round without progress.
    #[arg(long, default_value_t = 1.0)]
    c_step: f64,
    /// Where the balancer uses the workers' speeds: ignored, picks, or offers-and-picks.
    #[arg(long, value_enum, default_value_t = SpeedUseArg::OffersAndPicks)]
    speed_use: SpeedUseArg,
    /// Süß's Figure 5.5 rule: a worker assigned in a round answers no later round of the group.
    #[arg(long)]
    answer_once_per_group: bool,
    /// Skip the baselines.
    #[arg(long)]
    no_baselines: bool,
    /// Where the reports go.
    #[arg(long)]
    out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Args)]
struct TraceArgs {
    /// A built-in walk-through: walk, orbit or bursts.
    #[arg(long)]
    synthetic: String,
    #[arg(long, default_value_t = 6000)]
    positions: u64,
    #[arg(long, default_value_t = 2000)]
    objects: u32,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The JSON Lines file to write.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum StrategyArg {
    Deterministic,
    Randomized,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum SpeedUseArg {
    Ignored,
    Picks,
    OffersAndPicks,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum CollisionArg {
    Count,
    Load,
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Simulate(args) => run_simulate(&args),
        Command::Scaling(args) => {
            let text = std::fs::read_to_string(&args.csv)
                .with_context(|| format!("reading {}", args.csv.display()))?;
            let rows =
                scaling::parse(&text).with_context(|| format!("in {}", args.csv.display()))?;
            std::fs::create_dir_all(&args.out)
                .with_context(|| format!("creating {}", args.out.display()))?;
            scaling::draw(&args.out, &rows)
        }
        Command::Trace(args) => {
            let trace = synthetic_trace(&args.synthetic, args.positions, args.objects, args.seed)
                .with_context(|| {
                format!(
                    "unknown synthetic walk-through {:?} (walk, orbit, bursts)",
                    args.synthetic
                )
            })?;
            std::fs::write(&args.out, trace.to_json_lines())
                .with_context(|| format!("writing {}", args.out.display()))
        }
    }
}

/// One row of the summary: a policy on one (nodes, replicas) pair, averaged over seeds.
#[derive(Debug, Serialize)]
struct SummaryRow {
    nodes: usize,
    replicas: usize,
    policy: String,
    seeds: u64,
    /// Mean over seeds of the mean busiest/lower-bound over positions with >= 2n requests
    /// (NaN, written as empty or null, when no position is that busy).
    busiest_over_bound_busy: f64,
    /// Seeds whose trace had busy positions (the mean's divisor).
    #[serde(skip)]
    busy_seeds: u64,
    /// The same over all positions with requests.
    busiest_over_bound_all: f64,
    /// Mean over seeds of the mean finish time over its bound, busy positions (NaN when
    /// none): see `PositionStats::finish_over_bound`.
    finish_over_bound_busy: f64,
    /// The same over all positions with requests.
    finish_over_bound_all: f64,
    /// Largest c over all seeds (balancer only).
    max_c: f64,
    /// Share of all weight the slowest workers got, over the mean share (1 = fair by count).
    slow_worker_share_ratio: Option<f64>,
}

fn run_simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let trace = load_trace(&args.source, args.positions, args.objects)?;
    if trace.records.is_empty() {
        bail!("the trace has no requests");
    }
    let speed_cycle = parse_speeds(&args.speeds)?;
    if args.nodes.contains(&0) || args.seeds == 0 {
        bail!("--nodes and --seeds must be positive");
    }
    for &k in &args.replicas {
        if let Some(&n) = args.nodes.iter().find(|&&n| k == 0 || k > n) {
            bail!("cannot place {k} replicas on {n} workers");
        }
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;

    let collision = match args.collision {
        CollisionArg::Count => Collision::Count,
        CollisionArg::Load => Collision::Load,
    };
    let mut policies: Vec<(String, Policy)> = args
        .strategy
        .iter()
        .map(|s| {
            let strategy = match s {
                StrategyArg::Deterministic => Strategy::Deterministic,
                StrategyArg::Randomized => Strategy::Randomized,
            };
            let config = Config {
                collision,
                strategy,
                c_start: args.c_start,
                c_step: args.c_step,
                speeds: match args.speed_use {
                    SpeedUseArg::Ignored => SpeedUse::Ignored,
                    SpeedUseArg::Picks => SpeedUse::Picks,
                    SpeedUseArg::OffersAndPicks => SpeedUse::OffersAndPicks,
                },
                answer_once_per_group: args.answer_once_per_group,
                ..Config::default()
            };
            (
                format!(
                    "c-{}-collision-{}",
                    if collision == Collision::Load {
                        "load"
                    } else {
                        "count"
                    },
                    strategy_name(strategy)
                ),
                Policy::Balancer(config),
            )
        })
        .collect();
    if !args.no_baselines {
        policies.extend(
            Baseline::ALL
                .iter()
                .map(|b| (b.name().to_string(), Policy::Baseline(*b))),
        );
    }

    let mut jobs = Vec::new();
    for &nodes in &args.nodes {
        for &replicas in &args.replicas {
            for (name, policy) in &policies {
                for seed in 0..args.seeds {
                    let speeds = (0..nodes)
                        .map(|w| speed_cycle[w % speed_cycle.len()])
                        .collect();
                    jobs.push((
                        name.clone(),
                        SimulationConfig {
                            workers: nodes,
                            replicas,
                            seed,
                            speeds,
                            base_speed: args.base_speed,
                            policy: policy.clone(),
                        },
                    ));
                }
            }
        }
    }
    let progress = indicatif::ProgressBar::new(jobs.len() as u64).with_message("simulating");
    progress.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let results: Vec<(String, SimulationConfig, SimulationResult)> = jobs
        .into_par_iter()
        .map(|(name, config)| {
            let result = simulate(&trace, &config);
            progress.inc(1);
            result.map(|r| (name, config, r))
        })
        .collect::<Result<_, _>>()?;
    progress.finish_and_clear();

    let summary = summarise(&results, &speed_cycle, args.seeds);
    write_reports(&args.out, &results, &summary)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "{:>5} {:>8}  {:<38} {:>12} {:>12} {:>12} {:>12} {:>6}",
            "nodes",
            "replicas",
            "policy",
            "busy/bound",
            "all/bound",
            "busy finish",
            "all finish",
            "max c"
        );
        // "-": no position had 2n requests.
        let busy = |v: f64| {
            if v.is_nan() {
                "-".to_string()
            } else {
                format!("{v:.3}")
            }
        };
        for row in &summary {
            println!(
                "{:>5} {:>8}  {:<38} {:>12} {:>12.3} {:>12} {:>12.3} {:>6}",
                row.nodes,
                row.replicas,
                row.policy,
                busy(row.busiest_over_bound_busy),
                row.busiest_over_bound_all,
                busy(row.finish_over_bound_busy),
                row.finish_over_bound_all,
                row.max_c
            );
        }
        println!("reports in {}", args.out.display());
    }
    Ok(())
}

fn strategy_name(strategy: Strategy) -> &'static str {
    match strategy {
        Strategy::Deterministic => "deterministic",
        Strategy::Randomized => "randomized",
    }
}

fn load_trace(source: &Source, positions: u64, objects: u32) -> anyhow::Result<Trace> {
    match (&source.trace, &source.synthetic) {
        (Some(path), _) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            Trace::from_json_lines(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
        }
        (None, Some(name)) => synthetic_trace(name, positions, objects, 1).with_context(|| {
            format!("unknown synthetic walk-through {name:?} (walk, orbit, bursts)")
        }),
        (None, None) => bail!("give --trace FILE or --synthetic NAME"),
    }
}

fn parse_speeds(spec: &str) -> anyhow::Result<Vec<f64>> {
    let speeds: Vec<f64> = spec
        .split(',')
        .map(|s| {
            s.trim()
                .parse::<f64>()
                .with_context(|| format!("bad speed {s:?} in --speeds"))
        })
        .collect::<anyhow::Result<_>>()?;
    if speeds.is_empty() || speeds.iter().any(|s| !(*s > 0.0 && s.is_finite())) {
        bail!("--speeds needs positive numbers, got {spec:?}");
    }
    Ok(speeds)
}

fn summarise(
    results: &[(String, SimulationConfig, SimulationResult)],
    speed_cycle: &[f64],
    seeds: u64,
) -> Vec<SummaryRow> {
    let mut rows: Vec<SummaryRow> = Vec::new();
    let slowest = speed_cycle.iter().copied().fold(f64::INFINITY, f64::min);
    let heterogeneous = speed_cycle.iter().any(|s| *s != slowest);
    for (name, config, result) in results {
        let row = match rows.iter_mut().find(|r| {
            r.nodes == config.workers && r.replicas == config.replicas && r.policy == *name
        }) {
            Some(row) => row,
            None => {
                rows.push(SummaryRow {
                    nodes: config.workers,
                    replicas: config.replicas,
                    policy: name.clone(),
                    seeds,
                    busiest_over_bound_busy: f64::NAN,
                    busy_seeds: 0,
                    busiest_over_bound_all: 0.0,
                    finish_over_bound_busy: f64::NAN,
                    finish_over_bound_all: 0.0,
                    max_c: 0.0,
                    slow_worker_share_ratio: heterogeneous.then_some(0.0),
                });
                rows.last_mut().unwrap_or_else(|| unreachable!())
            }
        };
        let busy = result.mean_busiest_over_bound_busy;
        if !busy.is_nan() {
            // A running mean over the seeds that had busy positions.
            row.busy_seeds += 1;
            let previous = if row.busy_seeds == 1 {
                0.0
            } else {
                row.busiest_over_bound_busy
            };
            row.busiest_over_bound_busy = previous + (busy - previous) / row.busy_seeds as f64;
            let previous = if row.busy_seeds == 1 {
                0.0
            } else {
                row.finish_over_bound_busy
            };
            row.finish_over_bound_busy =
                previous + (result.mean_finish_over_bound_busy - previous) / row.busy_seeds as f64;
        }
        row.busiest_over_bound_all += result.mean_busiest_over_bound / seeds as f64;
        row.finish_over_bound_all += result.mean_finish_over_bound / seeds as f64;
        row.max_c = row.max_c.max(result.max_c);
        if let Some(ratio) = row.slow_worker_share_ratio.as_mut() {
            let slow: Vec<f64> = result
                .worker_shares
                .iter()
                .zip(&config.speeds)
                .filter(|(_, s)| **s == slowest)
                .map(|(w, _)| *w)
                .collect();
            let mean_share = 1.0 / config.workers as f64;
            *ratio +=
                slow.iter().sum::<f64>() / slow.len().max(1) as f64 / mean_share / seeds as f64;
        }
    }
    rows
}

fn write_reports(
    out: &Path,
    results: &[(String, SimulationConfig, SimulationResult)],
    summary: &[SummaryRow],
) -> anyhow::Result<()> {
    std::fs::write(
        out.join("summary.json"),
        serde_json::to_string_pretty(summary)?,
    )?;
    let mut csv = String::from(
        "nodes,replicas,policy,seeds,busiest_over_bound_busy,busiest_over_bound_all,finish_over_bound_busy,finish_over_bound_all,max_c,slow_worker_share_ratio\n",
    );
    let or_empty = |v: f64| {
        if v.is_nan() {
            String::new()
        } else {
            format!("{v:.6}")
        }
    };
    for r in summary {
        csv += &format!(
            "{},{},{},{},{},{:.6},{},{:.6},{},{}\n",
            r.nodes,
            r.replicas,
            r.policy,
            r.seeds,
            or_empty(r.busiest_over_bound_busy),
            r.busiest_over_bound_all,
            or_empty(r.finish_over_bound_busy),
            r.finish_over_bound_all,
            r.max_c,
            r.slow_worker_share_ratio
                .map(|v| format!("{v:.6}"))
                .unwrap_or_default()
        );
    }
    std::fs::write(out.join("summary.csv"), csv)?;
    // Per position, seed 0 of every configuration (all seeds would repeat the same shape).
    for (name, config, result) in results.iter().filter(|(_, c, _)| c.seed == 0) {
        let mut csv = String::from(
            "frame,requests,total_weight,median_share,q10_share,q90_share,busiest_over_bound,finish_over_bound,max_c\n",
        );
        for p in &result.positions {
            csv += &format!(
                "{},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{}\n",
                p.frame,
                p.requests,
                p.total_weight,
                p.median_share,
                p.q10_share,
                p.q90_share,
                p.busiest_over_bound,
                p.finish_over_bound,
                p.max_c
            );
        }
        std::fs::write(
            out.join(format!(
                "positions-n{}-k{}-{name}.csv",
                config.workers, config.replicas
            )),
            csv,
        )?;
    }
    plots::draw(
        out,
        results,
        summary
            .iter()
            .map(|r| {
                (
                    r.nodes,
                    r.replicas,
                    r.policy.as_str(),
                    r.busiest_over_bound_busy,
                )
            })
            .collect(),
    )
}
