//! Where SIFT's time goes: for the first 40 images of a folder, decoded
//! and downscaled as the service does (its 640 px frame, its SIFT
//! parameters, one OpenCV thread), the median time of OpenCV's whole
//! `detectAndCompute`, of detection alone (scale space, extrema,
//! orientations), and of describing given keypoints (all of them, then every
//! second one), which builds the Gaussian pyramid again. It bounds what
//! describing keypoints on demand, as the voter asks for them, could save
//! (docs/performance.md, "Where SIFT's time goes").
//!
//! ```sh
//! cargo run --release --example sift_split -- ../shared/datasets/gardens-point/day_left
//! ```

use bowloc::eval::machine::cpu_from;
use bowloc::features::{DecodeLimits, ExtractConfig, Frame, decode_file};
use opencv::core::{KeyPoint, Mat, Vector, no_array};
use opencv::prelude::*;
use std::time::Instant;

const IMAGES: usize = 40;
const RUNS: usize = 3;

fn main() -> anyhow::Result<()> {
    let dir = std::env::args()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("usage: sift_split IMAGE_FOLDER"))?;
    opencv::core::set_num_threads(1)?;
    let config = ExtractConfig::default();
    let mut files: Vec<_> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "jpg" || e == "png"))
        .collect();
    files.sort();
    files.truncate(IMAGES);
    anyhow::ensure!(!files.is_empty(), "no .jpg or .png images in {dir}");
    let [
        mut whole,
        mut detect,
        mut describe_all,
        mut describe_half,
        mut keypoints,
    ] = [(); 5].map(|_| Vec::<f64>::new());
    let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
    for f in &files {
        let image = decode_file(f, DecodeLimits::default(), config.max_side)?;
        let mut frame = Frame::new(&image, &config)?;
        let (frame, sift) = frame.parts();
        for _ in 0..RUNS {
            let (mut found, mut descriptors) = (Vector::<KeyPoint>::new(), Mat::default());
            let t = Instant::now();
            sift.detect_and_compute(frame, &no_array(), &mut found, &mut descriptors, false)?;
            whole.push(ms(t));
            keypoints.push(found.len() as f64);

            let mut detected = Vector::<KeyPoint>::new();
            let t = Instant::now();
            sift.detect(frame, &mut detected, &no_array())?;
            detect.push(ms(t));

            for (subset, times) in [
                (detected.clone(), &mut describe_all),
                (detected.iter().step_by(2).collect(), &mut describe_half),
            ] {
                let (mut given, mut out) = (subset, Mat::default());
                let t = Instant::now();
                sift.detect_and_compute(frame, &no_array(), &mut given, &mut out, true)?;
                times.push(ms(t));
            }
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let (cpu, level) = cpu_from(&cpuinfo);
    let w = median(&mut whole);
    println!(
        "{} images x {RUNS} runs on {cpu} ({level}), {} px, one thread; median keypoints {}",
        files.len(),
        config.max_side,
        median(&mut keypoints)
    );
    for (name, v) in [
        ("detect + describe (one call)", &mut whole),
        ("detect alone", &mut detect),
        ("describe all keypoints given", &mut describe_all),
        ("describe every second one given", &mut describe_half),
    ] {
        let m = median(v);
        println!("{name:32} median {m:6.2} ms  {:.2}x", m / w);
    }
    Ok(())
}
