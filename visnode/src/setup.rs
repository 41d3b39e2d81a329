//! From flags to a running [`Viewer`]: load and prepare the scene, open the renderer, make the
//! far field the flags ask for (finding or starting workers and storing the objects on them
//! when it uses boards), upload the meshes. Shared by `bench` and the window.

use crate::board::BoardShape;
use crate::cli::{BoardArgs, Impostor, SceneArgs, WorkerArgs};
use crate::plan::PlanParams;
use crate::render::Renderer;
use crate::viewer::{Viewer, ViewerOptions};
use crate::workers::{BoardRequests, Credentials, StoredObjects, Workers};
use std::sync::Arc;

/// What was set up.
pub struct Setup {
    /// The frame loop.
    pub viewer: Viewer,
    /// Preprocessing's summary.
    pub summary: scene::Summary,
}

/// Plan parameters from flags.
pub fn plan_params(scene: &SceneArgs, boards: &BoardArgs) -> PlanParams {
    PlanParams {
        t_nz: scene.t_nz(),
        epsilon_degrees: boards.epsilon,
        refresh_pixels: boards.refresh_pixels,
        e_degrees: boards.max_angle,
        map_size: scene.map_size,
        texels_per_pixel: boards.texels_per_pixel,
        impostors: boards.impostor != Impostor::None,
        triangle_cost_pixels: boards.triangle_cost_pixels,
        ..PlanParams::default()
    }
}

/// Loads the scene and builds the viewer on an offscreen renderer; `sync` makes frames wait
/// for their boards.
pub fn setup(
    scene_args: &SceneArgs,
    worker_args: &WorkerArgs,
    board_args: &BoardArgs,
    sync: bool,
    record_trace: bool,
) -> anyhow::Result<Setup> {
    check_flags(board_args)?;
    let scene = load_scene(scene_args)?;
    let renderer = Renderer::new(scene_args.resolution)?;
    build(
        scene,
        renderer,
        scene_args,
        worker_args,
        board_args,
        sync,
        record_trace,
    )
}

/// Rejects flag combinations that cannot work, before any slow work starts (each flag's own
/// range is checked when it is parsed, in `cli`).
pub fn check_flags(board_args: &BoardArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        board_args.epsilon < board_args.max_angle,
        "need --epsilon < --max-angle, got {} and {} degrees",
        board_args.epsilon,
        board_args.max_angle
    );
    Ok(())
}

/// A loaded and prepared scene, with which objects may become boards. The objects are
/// shared, never copied: the renderer uploads them, workers in this process and the store
/// kept for restarted workers hold the same ones (cloning a loaded scene is cheap).
#[derive(Clone)]
pub struct LoadedScene {
    pub(crate) objects: Arc<Vec<scene::Object>>,
    pub(crate) summary: scene::Summary,
    /// Per object: whether it may become a board.
    pub(crate) suitable: Vec<bool>,
    /// Per object: its largest board side as a multiple of the map size.
    pub(crate) map_scales: Vec<u32>,
}

/// Loads and prepares the scene (clustering where it needs it, cached).
pub fn load_scene(scene_args: &SceneArgs) -> anyhow::Result<LoadedScene> {
    let (prepared, _) = crate::inspect::inspect(scene_args)?;
    let suitable = prepared
        .classes
        .iter()
        .map(|c| *c == scene::ObjectClass::Suitable)
        .collect();
    Ok(LoadedScene {
        objects: Arc::new(prepared.objects),
        summary: prepared.summary,
        suitable,
        map_scales: prepared.map_scales,
    })
}

/// Starts or connects the workers, stores the scene on them and uploads it to `renderer`.
pub fn build(
    scene: LoadedScene,
    mut renderer: Renderer,
    scene_args: &SceneArgs,
    worker_args: &WorkerArgs,
    board_args: &BoardArgs,
    sync: bool,
    record_trace: bool,
) -> anyhow::Result<Setup> {
    renderer.board_depth = board_args.board_depth;
    renderer.soft_edges = board_args.soft_edges;
    let progress = crate::progress::bar();
    let far_field =
        crate::far_field::for_kind(board_args, worker_args, &scene, record_trace, &progress);
    let options = ViewerOptions {
        plan: plan_params(scene_args, board_args),
        fade_frames: board_args.fade_frames,
        fade_pixels: board_args.fade_pixels,
        sync,
        upload_budget: std::time::Duration::from_secs_f64(board_args.upload_ms / 1e3),
        still_upload_budget: std::time::Duration::from_secs_f64(board_args.still_upload_ms / 1e3),
        ..ViewerOptions::default()
    };
    let LoadedScene {
        objects,
        summary,
        suitable,
        map_scales,
    } = scene;
    // Objects drawn as geometry beyond the near zone go through levels of detail, whatever
    // stands in for the suitable ones (geometry only keeps them whole: `Viewer::new`).
    let geometry_lod = crate::viewer::GeometryLod {
        pixels: board_args.lod_pixels,
        whole_unsuitable: board_args.whole_unsuitable,
        cache_dir: scene_args.cache_directory(),
    };
    let mut viewer = Viewer::new(
        renderer,
        &objects,
        &suitable,
        far_field,
        options,
        Some(geometry_lod),
        &progress,
    )?;
    viewer.set_map_scales(&map_scales);
    progress.finish_and_clear();
    Ok(Setup { viewer, summary })
}

/// The workers the flags name (`--workers`, `--workers-dns`), or in-process ones. A DNS name
/// is followed while running ([`Workers::follow`]); at start it may take up to 30 s to resolve
/// (workers started beside this node may not be up yet).
pub fn connect_workers(args: &WorkerArgs) -> anyhow::Result<Workers> {
    let mut addresses = args.workers.clone();
    if let Some(name) = &args.workers_dns {
        let give_up = std::time::Instant::now() + std::time::Duration::from_secs(30);
        let resolved = loop {
            match crate::workers::resolve_all(name) {
                Ok(resolved) => break resolved,
                Err(error) if std::time::Instant::now() > give_up => return Err(error),
                Err(_) => std::thread::sleep(std::time::Duration::from_millis(500)),
            }
        };
        addresses.extend(resolved);
    }
    let mut workers = if addresses.is_empty() {
        Workers::start_local(args.local_workers, args.worker_threads)?
    } else {
        let credentials = Credentials {
            token: args.token.clone().filter(|t| !t.is_empty()),
            tls_ca: args.tls_ca.clone(),
            tls_identity: args.tls_cert.clone().zip(args.tls_key.clone()),
            tls_domain: args.tls_domain.clone(),
        };
        Workers::connect(&addresses, &credentials)?
    };
    if let Some(name) = args.workers_dns.clone() {
        let fixed = args.workers.clone();
        workers.follow(
            move || {
                let mut listed = fixed.clone();
                listed.extend(crate::workers::resolve_all(&name)?);
                Ok(listed)
            },
            std::time::Duration::from_secs_f64(args.dns_interval),
        );
    }
    workers.deadlines.render = std::time::Duration::from_millis(args.request_timeout_ms);
    Ok(workers)
}

/// Places the suitable objects on `workers` (`replicas` each, at random), stores them there
/// and returns the requests over them. Workers that cannot store are marked down (health
/// probes bring them back); an error when none can.
pub fn requests_on(
    workers: Workers,
    objects: &Arc<Vec<scene::Object>>,
    suitable: &[bool],
    replicas: usize,
    shape: BoardShape,
    record_trace: bool,
    progress: &indicatif::ProgressBar,
) -> Result<BoardRequests, String> {
    let replicas = replicas.clamp(1, workers.len());
    let placement = balancer::Placement::random(objects.len(), workers.len(), replicas, 7)
        .map_err(|e| e.to_string())?;
    let stored: Vec<(u32, &scene::Object)> = objects
        .iter()
        .enumerate()
        .filter(|(id, _)| suitable[*id])
        .map(|(id, object)| (id as u32, object))
        .collect();
    let failed = workers.store(&stored, &placement, progress);
    for (worker, why) in &failed {
        eprintln!(
            "worker {} is not used: {why}",
            workers.addresses[*worker as usize]
        );
    }
    if failed.len() == workers.len() {
        return Err(format!(
            "no worker could store the scene ({})",
            failed.first().map_or("", |(_, why)| why.as_str())
        ));
    }
    // The first frames get boards from the levels, as every figure measured so far did; a
    // worker that joins later is used at once.
    workers.until_simplified(progress);
    let weights = objects.iter().map(|o| o.triangle_count() as f64).collect();
    let mut requests = BoardRequests::new(
        workers,
        placement,
        weights,
        shape,
        record_trace,
        StoredObjects::new(objects.clone(), suitable.to_vec()),
    )
    .map_err(|e| e.to_string())?;
    for (worker, why) in failed {
        requests.mark_dead(worker, &why);
    }
    Ok(requests)
}
