//! `doma view` in a real browser: headless Chromium (Debian's package; `.ci/run` installs
//! it) opens the page from a file, with no network, and the test reads the screenshots'
//! pixels: the object covers a region around the centre, it is coloured by error, and two
//! frames differ. For a run with a mesh, for a point cloud, and for a run whose folder's
//! name is hostile HTML.

use crate::common;

use std::path::Path;
use std::process::Command;

use common::png::{Image, decode};

const FAERIE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/md2_faerie.traj");
const FLUID: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/taichi_mpm3d_fluid.traj");
const BACKGROUND: [u8; 3] = [27, 29, 34];
const CHROMIUM: &str = "/usr/bin/chromium";

fn temp(tag: &str) -> common::Scratch {
    common::scratch(&format!("doma-view-{tag}"))
}

fn doma(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The page at `fragment`, rendered by headless Chromium (software WebGL).
fn screenshot(page: &Path, fragment: &str, dir: &Path) -> Image {
    let shot = dir.join(format!("shot-{}.png", fragment.replace(['=', '&'], "_")));
    let profile = dir.join(format!("profile-{}", fragment.replace(['=', '&'], "_")));
    let out = Command::new(CHROMIUM)
        .args([
            "--headless",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--ignore-gpu-blocklist",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--force-device-scale-factor=1",
            "--window-size=800,600",
            "--virtual-time-budget=4000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", shot.display()))
        .arg(format!("file://{}#{fragment}", page.display()))
        .output()
        .unwrap();
    let bytes = std::fs::read(&shot).unwrap_or_else(|e| {
        panic!(
            "no screenshot ({e}): {}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    decode(&bytes).unwrap()
}

/// The drawing area: below the title and legend, above the control panel.
fn scene_pixels(img: &Image) -> impl Iterator<Item = (usize, usize, [u8; 4])> + '_ {
    (60..img.height - 70).flat_map(move |y| (0..img.width).map(move |x| (x, y, img.pixel(x, y))))
}

fn is_object(p: [u8; 4]) -> bool {
    (0..3).any(|c| (p[c] as i32 - BACKGROUND[c] as i32).abs() > 24)
}

/// Checks one page: coverage around the centre, colours from the error ramp, and two
/// frames that differ.
fn check_page(page: &Path, dir: &Path, last: usize) {
    let first = screenshot(page, "frame=0", dir);
    let later = screenshot(page, &format!("frame={last}"), dir);
    assert_eq!((first.width, first.height), (800, 600));
    let area = (first.height - 130) * first.width;
    let object: Vec<(usize, usize)> = scene_pixels(&first)
        .filter(|&(_, _, p)| is_object(p))
        .map(|(x, y, _)| (x, y))
        .collect();
    let share = object.len() as f64 / area as f64;
    assert!(
        share > 0.01 && share < 0.8,
        "the object covers {:.1} % of the scene",
        100.0 * share
    );
    let cx = object.iter().map(|p| p.0).sum::<usize>() as f64 / object.len() as f64;
    let cy = object.iter().map(|p| p.1).sum::<usize>() as f64 / object.len() as f64;
    assert!(
        (cx - 400.0).abs() < 160.0 && (cy - 300.0).abs() < 140.0,
        "centroid ({cx:.0}, {cy:.0})"
    );
    // Coloured by error: saturated pixels (the ramp), not only grey.
    let colourful = scene_pixels(&first)
        .filter(|&(_, _, p)| p[..3].iter().max().unwrap() - p[..3].iter().min().unwrap() > 60)
        .count();
    assert!(colourful > 100, "{colourful} coloured pixels");
    let changed = scene_pixels(&first)
        .filter(|&(x, y, p)| {
            let q = later.pixel(x, y);
            (0..3).any(|c| (p[c] as i32 - q[c] as i32).abs() > 24)
        })
        .count();
    assert!(
        changed as f64 > 0.002 * area as f64,
        "frames 0 and {last} differ in {changed} pixels"
    );
    // The legend is drawn (the ramp's red end at the top right).
    let red = (600..800)
        .flat_map(|x| (0..60).map(move |y| (x, y)))
        .filter(|&(x, y)| {
            let p = first.pixel(x, y);
            p[0] > 180 && p[1] < 90 && p[2] < 90
        })
        .count();
    assert!(red > 10, "no legend ramp");
}

#[test]
fn the_viewer_renders_a_mesh_run_and_a_point_run_in_chromium() {
    if !common::tool_or_skip(
        "the_viewer_renders_a_mesh_run_and_a_point_run_in_chromium",
        "chromium (apt-get install chromium)",
        Path::new(CHROMIUM).is_file(),
    ) {
        return;
    }
    let dir = temp("chromium");
    // The third run's folder name would keep the page's script element open to the end
    // of the file if it reached the page unescaped (`<!--<script>`): the viewer must run.
    let hostile = "<!--<script>x";
    for (name, data, frames, last) in [
        ("mesh", FAERIE, "112..120", 7),
        ("points", FLUID, "0..30", 29),
        (hostile, FAERIE, "112..120", 7),
    ] {
        let run = dir.join(name);
        let page = dir.join(format!(
            "{}.html",
            if name == hostile { "hostile" } else { name }
        ));
        let (run_s, page_s) = (run.to_str().unwrap(), page.to_str().unwrap());
        doma(&[
            "fit", data, "--frames", frames, "--iters", "3", "--quiet", "--out", run_s,
        ]);
        doma(&["view", run_s, "--out", page_s]);
        let html = std::fs::read_to_string(&page).unwrap();
        // Self-contained: nothing is fetched.
        assert!(!html.contains("http://") && !html.contains("https://") && !html.contains("src="));
        assert!(
            !html.contains(hostile),
            "the run's name reached the page unescaped"
        );
        check_page(&page, &dir, last);
    }
}

/// A tracker's view of the faerie's "wave" clip (a TAPVid-3D file), fitted with its mesh.
pub(crate) fn masked_run(dir: &Path) -> std::path::PathBuf {
    let (view, obj) = common::faerie_tracker_view(112..120);
    let npz = dir.join("clip.npz");
    view.write(&npz, doma::data::layout::Layout::TapVid3d)
        .unwrap();
    let run = dir.join("masked");
    doma(&[
        "fit",
        npz.to_str().unwrap(),
        "--mesh",
        obj.to_str().unwrap(),
        "--drop-unobserved",
        "--iters",
        "3",
        "--quiet",
        "--out",
        run.to_str().unwrap(),
    ]);
    run
}

#[test]
fn the_viewer_shows_the_filled_points_of_tracks_with_gaps_in_their_own_colour() {
    if !common::tool_or_skip(
        "the_viewer_shows_the_filled_points_of_tracks_with_gaps_in_their_own_colour",
        "chromium (apt-get install chromium)",
        Path::new(CHROMIUM).is_file(),
    ) {
        return;
    }
    let dir = temp("filled");
    let run = masked_run(&dir);
    let page = dir.join("masked.html");
    doma(&[
        "view",
        run.to_str().unwrap(),
        "--out",
        page.to_str().unwrap(),
        "--up",
        "y",
    ]);
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.contains("\"up\":1") && !html.contains("\"observed\":null"));
    let shot = screenshot(&page, "frame=0", &dir);
    // The filled colour (217, 77, 217), shaded on the mesh.
    let magenta = scene_pixels(&shot)
        .filter(|&(_, _, p)| p[1] < 100 && p[0] > 100 && p[2] > 100 && p[0].abs_diff(p[2]) < 30)
        .count();
    assert!(magenta > 100, "{magenta} filled-colour pixels");
}

/// `doma complete --blend FILE` writes the weights it prints, with each class's held-out
/// figures: a choice never worse there than the best filler alone, as printed.
#[test]
fn complete_writes_the_blend_it_prints() {
    let dir = temp("blend");
    let run = masked_run(&dir);
    let (out, blend) = (dir.join("filled.npz"), dir.join("blend.json"));
    let output = Command::new(env!("CARGO_BIN_EXE_doma"))
        .args(["complete", run.to_str().unwrap(), "--out"])
        .args([out.as_os_str(), "--blend".as_ref(), blend.as_os_str()])
        .output()
        .unwrap();
    let printed = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{printed}");
    let text = std::fs::read_to_string(&blend).unwrap();
    let b: doma::gaps::blend::Blend = serde_json::from_str(&text).unwrap();
    assert!(b.validated.iter().sum::<usize>() > 0, "{text}");
    // Short and pooled long gaps, and a class on its own weights, never worse held out
    // than their best filler alone; a class on the pooled weights may be.
    let own = b.by_length.iter().filter(|c| c.own).map(|c| &c.held_out);
    let bounded: Vec<_> = b.held_out.iter().chain(own).flatten().collect();
    assert!(!bounded.is_empty(), "{text}");
    for h in bounded {
        assert!(h.chosen <= h.best_alone * (1.0 + 1e-9), "{h:?}");
    }
    let every = b
        .held_out
        .iter()
        .chain(b.by_length.iter().map(|c| &c.held_out));
    for h in every.flatten() {
        assert!(
            h.chosen.is_finite() && h.best_alone >= 0.0 && h.spans > 0.0,
            "{h:?}"
        );
        let line = format!("({} alone ", h.best.label());
        assert!(printed.contains(&line), "{printed}");
    }
}
