//! Hamming embedding prototype: recall of tf-idf voting with and without
//! per-feature binary signatures, at several fractions of the query features.
use bowloc::dataset::Dataset;
use bowloc::eval::cache;
use bowloc::features::{ExtractConfig, TileGrid};
use bowloc::quantize::Quantizer;
use bowloc::vocabulary::kmeans::KmeansConfig;
use ndarray::{Array2, ArrayView2};
use rand::{RngExt, SeedableRng};
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;

const BITS: usize = 64;

fn projection(dim: usize, seed: u64) -> Array2<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut p = Array2::<f32>::zeros((BITS, dim));
    for i in 0..BITS {
        let mut row: Vec<f32> = (0..dim)
            .map(|_| {
                // Box-Muller
                let u: f32 = rng.random::<f32>().max(1e-9);
                let v: f32 = rng.random::<f32>();
                (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * v).cos()
            })
            .collect();
        for k in 0..i {
            let d: f32 = (0..dim).map(|c| row[c] * p[[k, c]]).sum();
            for c in 0..dim {
                row[c] -= d * p[[k, c]];
            }
        }
        let n = row.iter().map(|x| x * x).sum::<f32>().sqrt();
        for c in 0..dim {
            p[[i, c]] = row[c] / n;
        }
    }
    p
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let root = PathBuf::from(args.get(1).cloned().unwrap_or("../shared/datasets/gardens-point".into()));
    let words_k: usize = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(5000);
    let vseed: u64 = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(1);
    let dataset = Dataset::open(&root)?;
    let cache_dir = PathBuf::from("data/eval-cache").join(&dataset.name);
    std::fs::create_dir_all(&cache_dir)?;
    let config = ExtractConfig::default();
    let (map, queries) = cache::dataset_descriptors(&cache_dir, &dataset, &config, TileGrid::WHOLE)?;
    let vocab = cache::vocabulary(&cache_dir, &map, &KmeansConfig { k: words_k, seed: vseed, ..KmeansConfig::default() })?;
    let quantizer = vocab.exact_quantizer();
    let words = |d: ArrayView2<'_, f32>| {
        let mut w = vec![0u32; d.nrows()];
        quantizer.quantize(d, &mut w);
        w
    };
    let dim = map.all().ncols();
    let p = projection(dim, 7);
    let n_img = map.len();
    // map features: word, projected
    let mut feats: Vec<(u32, u32, Vec<f32>)> = Vec::new(); // image, word, proj
    for j in 0..n_img {
        if let Some(d) = map.image(j) {
            let w = words(d);
            let pr = d.dot(&p.t());
            for (r, &wi) in w.iter().enumerate() {
                feats.push((j as u32, wi, pr.row(r).to_vec()));
            }
        }
    }
    // per-word medians
    let mut by_word: Vec<Vec<usize>> = vec![Vec::new(); words_k];
    for (i, f) in feats.iter().enumerate() {
        by_word[f.1 as usize].push(i);
    }
    let mut medians = vec![vec![0f32; BITS]; words_k];
    for w in 0..words_k {
        if by_word[w].is_empty() {
            continue;
        }
        for b in 0..BITS {
            let mut v: Vec<f32> = by_word[w].iter().map(|&i| feats[i].2[b]).collect();
            v.sort_by(|a, b| a.total_cmp(b));
            medians[w][b] = v[v.len() / 2];
        }
    }
    let sig = |w: u32, pr: &[f32]| -> u64 {
        let m = &medians[w as usize];
        let mut s = 0u64;
        for b in 0..BITS {
            if pr[b] > m[b] {
                s |= 1 << b;
            }
        }
        s
    };
    let mut lists: Vec<Vec<(u32, u64)>> = vec![Vec::new(); words_k];
    let mut tf = vec![std::collections::HashMap::<u32, f32>::new(); n_img];
    for f in &feats {
        lists[f.1 as usize].push((f.0, sig(f.1, &f.2)));
        *tf[f.0 as usize].entry(f.1).or_default() += 1.0;
    }
    let df: Vec<f32> = (0..words_k)
        .map(|w| {
            let mut imgs: Vec<u32> = lists[w].iter().map(|e| e.0).collect();
            imgs.dedup();
            imgs.len() as f32
        })
        .collect();
    let idf: Vec<f32> = df.iter().map(|&d| if d > 0.0 { (n_img as f32 / d).ln() } else { 0.0 }).collect();
    let norm: Vec<f32> = tf
        .iter()
        .map(|m| m.iter().map(|(w, t)| (t * idf[*w as usize]).powi(2)).sum::<f32>().sqrt().max(1e-9))
        .collect();

    let fractions = [0.25f32, 0.5, 0.75, 1.0];
    let settings: Vec<(String, u32, f32)> = vec![
        ("tf-idf".into(), 64, 0.0),
        ("HE h<=20".into(), 20, 0.0),
        ("HE h<=24".into(), 24, 0.0),
        ("HE h<=28".into(), 28, 0.0),
        ("HE h<=24 gauss16".into(), 24, 16.0),
        ("HE h<=28 gauss16".into(), 28, 16.0),
    ];
    let runs = 3;
    for (name, ht, sigma) in &settings {
        let mut line = format!("{name:<20}");
        for &f in &fractions {
            let (mut r1, mut r5, mut tot) = (0usize, 0usize, 0usize);
            for run in 0..runs {
                for qi in 0..queries.len() {
                    let Some(qd) = queries.image(qi) else { continue };
                    if dataset.truth[qi].is_empty() {
                        continue;
                    }
                    let qw = words(qd);
                    let qp = qd.dot(&p.t());
                    let mut order: Vec<usize> = (0..qw.len()).collect();
                    order.shuffle(&mut ChaCha8Rng::seed_from_u64(1000 * run + qi as u64));
                    let take = ((qw.len() as f32 * f).ceil() as usize).min(qw.len());
                    let mut score = vec![0f32; n_img];
                    for &r in &order[..take] {
                        let w = qw[r];
                        let s = sig(w, qp.row(r).as_slice().unwrap());
                        let wt = idf[w as usize] * idf[w as usize];
                        for &(j, ms) in &lists[w as usize] {
                            let h = (s ^ ms).count_ones();
                            if h <= *ht {
                                let g = if *sigma > 0.0 { (-(h as f32 / sigma).powi(2)).exp() } else { 1.0 };
                                score[j as usize] += wt * g;
                            }
                        }
                    }
                    let mut rank: Vec<usize> = (0..n_img).collect();
                    rank.sort_by(|&a, &b| (score[b] / norm[b]).total_cmp(&(score[a] / norm[a])));
                    tot += 1;
                    if dataset.truth[qi].contains(&(rank[0] as u32)) {
                        r1 += 1;
                    }
                    if rank[..5].iter().any(|&j| dataset.truth[qi].contains(&(j as u32))) {
                        r5 += 1;
                    }
                }
            }
            line += &format!("  f={f}: {:.1}/{:.1}", 100.0 * r1 as f64 / tot as f64, 100.0 * r5 as f64 / tot as f64);
        }
        println!("{line}");
    }
    Ok(())
}
