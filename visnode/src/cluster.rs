//! `visnode cluster`: a real cluster on one machine. Starts backend workers as separate
//! processes on loopback ports, then runs the window or the benchmark against them exactly
//! as against remote workers. [`WorkerProcesses`] is also what the fault tests use to kill,
//! hang and restart workers.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use anyhow::{Context, anyhow};

use crate::cli::{ClusterArgs, ClusterRun};

/// Runs `visnode cluster`.
pub fn run(args: &ClusterArgs) -> anyhow::Result<()> {
    let backend = match &args.backend {
        Some(path) => path.clone(),
        None => default_backend_binary(),
    };
    let specs: Vec<WorkerSpec> = (0..args.count)
        .map(|i| WorkerSpec {
            threads: args.threads,
            slowdown: args
                .slowdown
                .get(i)
                .or(args.slowdown.last())
                .copied()
                .unwrap_or(1.0),
            ..WorkerSpec::default()
        })
        .collect();
    let workers = WorkerProcesses::start(&backend, &specs)?;
    eprintln!(
        "started {} worker processes: {}",
        workers.len(),
        workers.addresses().join(", ")
    );
    let mut run = args
        .run
        .clone()
        .unwrap_or_else(|| ClusterRun::View(crate::cli::ViewArgs::defaults()));
    let worker_args = match &mut run {
        ClusterRun::View(view) => &mut view.workers,
        ClusterRun::Bench(bench) => &mut bench.workers,
    };
    anyhow::ensure!(
        worker_args.workers.is_empty() && worker_args.workers_dns.is_none(),
        "visnode cluster starts its own workers: give no --workers or --workers-dns after the subcommand"
    );
    worker_args.workers = workers.addresses().to_vec();
    let result = match &run {
        ClusterRun::View(view) => crate::gui::run(view),
        ClusterRun::Bench(bench) => crate::bench::run(bench),
    };
    drop(workers);
    result
}

/// `backend` beside this executable (how cargo and the release archive lay them out), else
/// whatever `backend` is on PATH.
pub fn default_backend_binary() -> PathBuf {
    std::env::current_exe()
        .ok()
        .map(|exe| exe.with_file_name("backend"))
        .filter(|path| path.exists())
        .unwrap_or_else(|| PathBuf::from("backend"))
}

/// How to start one worker.
#[derive(Debug, Clone)]
pub struct WorkerSpec {
    /// Render threads.
    pub threads: usize,
    /// Slowdown factor (`--slowdown`).
    pub slowdown: f64,
    /// Render requests queued at once (`--queue`).
    pub queue: usize,
    /// Shared token, if any.
    pub token: Option<String>,
    /// More `backend serve` flags (`--tls-cert ...`).
    pub extra_args: Vec<String>,
}

impl Default for WorkerSpec {
    fn default() -> Self {
        WorkerSpec {
            threads: 1,
            slowdown: 1.0,
            queue: 64,
            token: None,
            extra_args: Vec::new(),
        }
    }
}

/// Backend worker processes on loopback, stopped when dropped.
pub struct WorkerProcesses {
    backend: PathBuf,
    specs: Vec<WorkerSpec>,
    children: Vec<Option<Child>>,
    addresses: Vec<String>,
}

/// How long a worker may take to start listening.
const START_TIMEOUT: Duration = Duration::from_secs(30);

impl WorkerProcesses {
    /// Starts one process per spec, each on a free loopback port.
    pub fn start(backend: &Path, specs: &[WorkerSpec]) -> anyhow::Result<WorkerProcesses> {
        let mut processes = WorkerProcesses {
            backend: backend.to_path_buf(),
            specs: specs.to_vec(),
            children: Vec::new(),
            addresses: Vec::new(),
        };
        for index in 0..specs.len() {
            let (child, address) = processes.spawn(index, "127.0.0.1:0")?;
            processes.children.push(Some(child));
            processes.addresses.push(address);
        }
        Ok(processes)
    }

    fn spawn(&self, index: usize, listen: &str) -> anyhow::Result<(Child, String)> {
        let spec = &self.specs[index];
        let mut command = Command::new(&self.backend);
        command
            .args(["serve", "--listen", listen])
            .args(["--threads", &spec.threads.to_string()])
            .args(["--slowdown", &spec.slowdown.to_string()])
            .args(["--queue", &spec.queue.to_string()])
            .args(&spec.extra_args)
            .env_remove("RELIEFBOARD_TOKEN")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        if let Some(token) = &spec.token {
            command.env("RELIEFBOARD_TOKEN", token);
        }
        let mut child = command.spawn().with_context(|| {
            format!(
                "starting {} (build it with `cargo build --release -p backend`, or name it with --backend)",
                self.backend.display()
            )
        })?;
        let stderr = child.stderr.take().expect("stderr is piped");
        // The worker prints its address first; everything after goes on to our stderr.
        let (found, address) = mpsc::channel();
        std::thread::spawn(move || {
            let mut found = Some(found);
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                match line.strip_prefix("backend worker listening on ") {
                    Some(at) if found.is_some() => {
                        let _ = found.take().map(|f| f.send(at.trim().to_string()));
                    }
                    _ => eprintln!("[worker {index}] {line}"),
                }
            }
        });
        match address.recv_timeout(START_TIMEOUT) {
            Ok(address) => Ok((child, address)),
            Err(_) => {
                let _ = child.kill();
                let status = child.wait().ok();
                Err(anyhow!(
                    "worker {index} did not start listening on {listen} ({status:?})"
                ))
            }
        }
    }

    /// `host:port` of each worker.
    pub fn addresses(&self) -> &[String] {
        &self.addresses
    }

    /// Number of workers.
    pub fn len(&self) -> usize {
        self.addresses.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.addresses.is_empty()
    }

    /// Process id of a running worker.
    pub fn pid(&self, index: usize) -> Option<u32> {
        self.children.get(index)?.as_ref().map(Child::id)
    }

    /// Kills a worker at once (SIGKILL): no draining, connections reset.
    pub fn kill(&mut self, index: usize) -> anyhow::Result<()> {
        if let Some(mut child) = self.children.get_mut(index).and_then(Option::take) {
            child.kill().context("killing a worker")?;
            child.wait()?;
        }
        Ok(())
    }

    /// Starts a killed worker again on its old address; it comes back empty.
    pub fn restart(&mut self, index: usize) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.children.get(index).is_some_and(Option::is_none),
            "worker {index} is running"
        );
        let listen = self.addresses[index].clone();
        let (child, _) = self.spawn(index, &listen)?;
        self.children[index] = Some(child);
        Ok(())
    }

    /// Freezes (`true`, SIGSTOP) or thaws (SIGCONT) a worker: frozen, its port still accepts
    /// connections but nothing answers, like a hung machine.
    pub fn freeze(&mut self, index: usize, frozen: bool) -> anyhow::Result<()> {
        let pid = self
            .pid(index)
            .ok_or_else(|| anyhow!("worker {index} is not running"))?;
        let signal = if frozen { "-STOP" } else { "-CONT" };
        let status = Command::new("kill")
            .args([signal, &pid.to_string()])
            .status()
            .context("running kill")?;
        anyhow::ensure!(status.success(), "kill {signal} {pid} failed");
        Ok(())
    }

    /// Peak resident memory of a running worker in bytes (Linux `VmHWM`).
    pub fn peak_memory_bytes(&self, index: usize) -> Option<u64> {
        crate::peak_memory_of(&self.pid(index)?.to_string())
    }
}

impl Drop for WorkerProcesses {
    fn drop(&mut self) {
        for index in 0..self.children.len() {
            // A frozen worker ignores everything but SIGKILL; thaw first so it can exit.
            let _ = self.freeze(index, false);
            let _ = self.kill(index);
        }
    }
}
