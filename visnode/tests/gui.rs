//! The window (`visnode view`) as a person gets it: under Xvfb on Mesa's CPU driver, with a
//! scripted camera, the screenshot shows the scene and the overlay; resized, it draws at the
//! new size and F12 saves it; Escape closes it cleanly; without a display the error says what
//! to do instead. (Xvfb runs no window manager, so minimising is not exercised here.)

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn visnode() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_visnode"));
    command.env("XDG_RUNTIME_DIR", std::env::temp_dir());
    command
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("visnode-gui-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// An X server on a free display number, stopped when dropped.
struct Xvfb {
    child: Child,
    display: String,
}

impl Xvfb {
    /// Starts one, trying another display number when a server exits at once (another
    /// process took the number between our check and its start); fails after 5 tries or a
    /// minute.
    fn start() -> Xvfb {
        // Distinct for each test of this process (they run in parallel), spread by pid.
        static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let base = 100 + std::process::id() % 400 * 8;
        // Made once here, before any server: two servers creating it at the same time on a
        // fresh machine left one of them without its socket file (it answered only on the
        // abstract socket, and the check below never saw it).
        static SOCKET_DIR: std::sync::Once = std::sync::Once::new();
        SOCKET_DIR.call_once(|| {
            use std::os::unix::fs::PermissionsExt;
            let dir = Path::new("/tmp/.X11-unix");
            if std::fs::create_dir(dir).is_ok() {
                std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o1777)).unwrap();
            }
        });
        let start = Instant::now();
        let mut exits = Vec::new();
        for _ in 0..5 {
            let number = (0..64)
                .map(|_| base + NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed))
                .find(|n| {
                    !Path::new(&format!("/tmp/.X11-unix/X{n}")).exists()
                        && !Path::new(&format!("/tmp/.X{n}-lock")).exists()
                })
                .expect("a free X display number");
            let child = Command::new("Xvfb")
                .args([
                    &format!(":{number}"),
                    "-screen",
                    "0",
                    "1280x1024x24",
                    "-nolisten",
                    "tcp",
                    // Without it the server resets whenever its last client leaves: each
                    // `xdotool` poll before the window connects would drop the window's
                    // connection attempt ("Failed to open connection to X server").
                    "-noreset",
                ])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("Xvfb (apt-get install xvfb; .ci/run installs it)");
            // Killed when dropped, also when this start fails.
            let mut server = Xvfb {
                child,
                display: format!(":{number}"),
            };
            loop {
                let answers = || {
                    Command::new("xdotool")
                        .env("DISPLAY", &server.display)
                        .arg("getdisplaygeometry")
                        .stdout(Stdio::null())
                        .stderr(Stdio::null())
                        .status()
                        .expect("xdotool (apt-get install xdotool; .ci/run installs it)")
                        .success()
                };
                // Ready when a client can talk to it (on Linux clients also reach it by its
                // abstract socket, so its socket file is not required).
                if answers() {
                    return server;
                }
                if let Some(status) = server.child.try_wait().unwrap() {
                    exits.push(format!(":{number} {status}"));
                    break;
                }
                assert!(
                    start.elapsed() < Duration::from_secs(60),
                    "Xvfb :{number} did not start within a minute"
                );
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        panic!("Xvfb did not start: {exits:?}");
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs `command` to the end, or kills it after `limit`: a hung window fails the test
/// instead of stalling CI.
fn output_within(command: &mut Command, limit: Duration) -> std::process::Output {
    let mut child = command
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            let output = child.wait_with_output().unwrap();
            panic!(
                "killed after {limit:?}: {}",
                String::from_utf8_lossy(&output.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    child.wait_with_output().unwrap()
}

/// RGBA pixels of a PNG.
fn load_png(path: &Path) -> (u32, u32, Vec<[u8; 4]>) {
    let pixmap = tiny_skia::Pixmap::load_png(path).unwrap();
    let pixels = pixmap
        .pixels()
        .iter()
        .map(|p| {
            let c = p.demultiply();
            [c.red(), c.green(), c.blue(), c.alpha()]
        })
        .collect();
    (pixmap.width(), pixmap.height(), pixels)
}

#[test]
fn the_window_shows_the_scene_with_the_overlay_under_xvfb() {
    let xvfb = Xvfb::start();
    let out = temp_dir("xvfb");
    let shot = out.join("shot.png");
    let frames = 30;
    let mut result = visnode();
    result
        .env("DISPLAY", &xvfb.display)
        .env_remove("WAYLAND_DISPLAY")
        .args([
            "view",
            "--scene",
            "forest",
            "--triangles",
            "600000",
            "--t-nz",
            "250000",
            "--no-cache",
            "--local-workers",
            "2",
            "--resolution",
            "800x600",
            "--replay",
            "orbit",
            "--replay-frames",
            &frames.to_string(),
            "--exit-after",
            &frames.to_string(),
            "--screenshot-on-exit",
        ])
        .arg(&shot);
    let result = output_within(&mut result, Duration::from_secs(300));
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!("saved {}", shot.display())),
        "{stderr}"
    );

    let note: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(shot.with_extension("json")).unwrap())
            .unwrap();
    let (width, height, pixels) = load_png(&shot);
    assert_eq!((width, height), (800, 600), "the window's size");
    assert_eq!(note["frame"], frames - 1);
    assert!(
        note["boards"].as_u64().unwrap() >= 1,
        "boards arrived: {note}"
    );

    // The overlay: two panels inside the image, each mostly egui's dark fill with light text.
    let rects: Vec<[f64; 4]> = serde_json::from_value(note["overlay"].clone()).unwrap();
    assert_eq!(rects.len(), 2, "statistics and controls: {note}");
    let in_rects = |x: u32, y: u32| {
        rects.iter().any(|r| {
            (x as f64) >= r[0] && (x as f64) < r[2] && (y as f64) >= r[1] && (y as f64) < r[3]
        })
    };
    for rect in &rects {
        assert!(rect[0] >= 0.0 && rect[2] <= width as f64 && rect[3] <= height as f64);
        assert!(
            rect[2] - rect[0] > 100.0 && rect[3] - rect[1] > 100.0,
            "{rect:?}"
        );
        let inside: Vec<[u8; 4]> = (rect[1] as u32..rect[3] as u32)
            .flat_map(|y| (rect[0] as u32..rect[2] as u32).map(move |x| (x, y)))
            .map(|(x, y)| pixels[(y * width + x) as usize])
            .collect();
        let dark = inside
            .iter()
            .filter(|p| p[..3].iter().all(|&c| c < 60))
            .count();
        let light = inside
            .iter()
            .filter(|p| p[..3].iter().all(|&c| c > 150))
            .count();
        assert!(
            dark * 2 > inside.len(),
            "panel {rect:?} is not dark: {dark}/{}",
            inside.len()
        );
        assert!(
            light * 200 > inside.len(),
            "panel {rect:?} has no text: {light}"
        );
    }

    // The scene, outside the overlay: sky and ground and trees, not one colour.
    let sky = [0.62f64, 0.74, 0.88].map(|c| (c * 255.0).round() as i32);
    let mut scene = 0;
    let mut sky_pixels = 0;
    let mut green = 0;
    let mut colours = std::collections::HashSet::new();
    for y in 0..height {
        for x in 0..width {
            if in_rects(x, y) {
                continue;
            }
            let p = pixels[(y * width + x) as usize];
            scene += 1;
            colours.insert([p[0], p[1], p[2]]);
            if (0..3).all(|c| (p[c] as i32 - sky[c]).abs() <= 3) {
                sky_pixels += 1;
            } else if p[1] > p[0] && p[1] > p[2] {
                green += 1;
            }
        }
    }
    assert!(sky_pixels * 20 > scene, "sky: {sky_pixels} of {scene}");
    assert!(green * 20 > scene, "ground and leaves: {green} of {scene}");
    assert!(colours.len() > 100, "only {} colours", colours.len());
}

#[test]
fn without_a_display_the_window_points_to_bench() {
    let result = visnode()
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .args(["view", "--scene", "forest", "--triangles", "600000"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(!result.status.success());
    assert!(stderr.contains("cannot open a window"), "{stderr}");
    assert!(stderr.contains("visnode bench"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    // It says so before loading the scene: no clustering progress, no workers.
    assert!(!stderr.contains("worker"), "{stderr}");
}

#[test]
fn view_is_what_runs_without_a_subcommand() {
    let result = visnode()
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(!result.status.success());
    assert!(stderr.contains("cannot open a window"), "{stderr}");
}

/// Runs `xdotool` against the Xvfb display.
fn xdotool(display: &str, args: &[&str]) -> String {
    let output = Command::new("xdotool")
        .env("DISPLAY", display)
        .args(args)
        .output()
        .expect("xdotool (apt-get install xdotool; .ci/run installs it)");
    assert!(output.status.success(), "xdotool {args:?}: {output:?}");
    String::from_utf8_lossy(&output.stdout).trim().to_string()
}

#[test]
fn the_window_resizes_saves_a_screenshot_on_f12_and_closes_on_escape() {
    let xvfb = Xvfb::start();
    let shots = temp_dir("keys");
    let mut child = visnode()
        .env("DISPLAY", &xvfb.display)
        .env_remove("WAYLAND_DISPLAY")
        .args([
            "view",
            "--scene",
            "forest",
            "--triangles",
            "300000",
            "--t-nz",
            "100000",
            "--no-cache",
            "--local-workers",
            "1",
            "--resolution",
            "640x480",
            "--screenshot-dir",
        ])
        .arg(&shots)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Poll for the window (not `search --sync`, which would wait forever if visnode died).
    let start = Instant::now();
    let window = loop {
        let found = Command::new("xdotool")
            .env("DISPLAY", &xvfb.display)
            .args(["search", "--name", "reliefboard"])
            .output()
            .expect("xdotool (apt-get install xdotool; .ci/run installs it)");
        let stdout = String::from_utf8_lossy(&found.stdout);
        if let Some(id) = stdout.lines().next() {
            break id.trim().to_string();
        }
        if let Some(status) = child.try_wait().unwrap() {
            let mut stderr = String::new();
            std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
            panic!("visnode exited ({status}) before its window appeared: {stderr}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no window after 2 minutes"
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    xdotool(&xvfb.display, &["windowsize", &window, "500", "300"]);
    std::thread::sleep(Duration::from_millis(500));
    xdotool(&xvfb.display, &["windowfocus", "--sync", &window]);
    let start = Instant::now();
    let shot = loop {
        // F12 again until a frame has been drawn at the new size and saved.
        xdotool(&xvfb.display, &["key", "--window", &window, "F12"]);
        std::thread::sleep(Duration::from_millis(500));
        let pngs: Vec<PathBuf> = std::fs::read_dir(&shots)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "png"))
            .collect();
        if let Some(png) = pngs.into_iter().next() {
            break png;
        }
        assert!(start.elapsed() < Duration::from_secs(120), "no screenshot");
    };
    xdotool(&xvfb.display, &["key", "--window", &window, "Escape"]);
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the window did not close on Escape"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(status.success(), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let (width, height, _) = load_png(&shot);
    assert_eq!((width, height), (500, 300), "drawn at the resized size");
}
