//! Approximate quantization for large vocabularies: a two-level k-means tree.
//! The K words are grouped around G centres (k-means over the words
//! themselves, done by `vocabulary`). A descriptor is compared with the G
//! centres, then exactly, with the packed kernels, with the words of its
//! `probes` nearest groups. It costs about G + probes·K/G distances instead of
//! K, and more probes give more agreement with exact search.

use super::{ExactQuantizer, Quantizer, kernels};
use ndarray::{Array2, ArrayView2};

/// The groups of a two-level tree over a vocabulary.
pub struct TreeQuantizer {
    dim: usize,
    k: usize,
    /// G × dim group centres, row-major.
    centres: Vec<f32>,
    centre_norms: Vec<f32>,
    /// Per group: the global ids of its words and their packed kernel.
    groups: Vec<(Vec<u32>, ExactQuantizer)>,
}

impl TreeQuantizer {
    /// `centroids` are the K words (`K × dim`), `centres` the G group centres
    /// (`G × dim`) and `group_of[w]` the group of word w.
    pub fn new(centroids: &[f32], dim: usize, centres: Vec<f32>, group_of: &[u32]) -> Self {
        let k = centroids.len() / dim;
        let g = centres.len() / dim;
        assert_eq!(group_of.len(), k, "one group per word");
        let mut members: Vec<Vec<u32>> = vec![Vec::new(); g];
        for (w, &grp) in group_of.iter().enumerate() {
            members[grp as usize].push(w as u32);
        }
        let groups = members
            .into_iter()
            .map(|ids| {
                let rows: Vec<f32> = ids
                    .iter()
                    .flat_map(|&w| &centroids[w as usize * dim..(w as usize + 1) * dim])
                    .copied()
                    .collect();
                let q = ExactQuantizer::new(&rows, dim);
                (ids, q)
            })
            .collect();
        let centre_norms = super::squared_norms(&centres, dim);
        Self {
            dim,
            k,
            centres,
            centre_norms,
            groups,
        }
    }

    pub fn groups(&self) -> usize {
        self.groups.len()
    }

    /// A quantizer searching the `probes` nearest groups of each descriptor.
    pub fn with_probes(&self, probes: usize) -> TreeSearch<'_> {
        TreeSearch {
            tree: self,
            probes: probes.clamp(1, self.groups.len().max(1)),
        }
    }
}

/// A [`TreeQuantizer`] with a number of probes.
pub struct TreeSearch<'a> {
    tree: &'a TreeQuantizer,
    probes: usize,
}

impl Quantizer for TreeSearch<'_> {
    fn words(&self) -> usize {
        self.tree.k
    }

    fn dim(&self) -> usize {
        self.tree.dim
    }

    fn quantize(&self, block: ArrayView2<'_, f32>, out: &mut [u32]) {
        let t = self.tree;
        let (b, dim) = (block.nrows(), t.dim);
        if b == 0 {
            return;
        }
        let block = block.as_standard_layout();
        let x = block.as_slice().expect("standard layout");
        let g = t.groups.len();
        // distances to every centre (up to ‖x‖²), then the nearest `probes`
        let mut dots = Vec::new();
        kernels::gemm_dots(x, dim, &t.centres, &mut dots);
        let mut probing: Vec<Vec<u32>> = vec![Vec::new(); g];
        let mut order: Vec<(f32, u32)> = Vec::with_capacity(g);
        for r in 0..b {
            order.clear();
            order.extend(
                dots[r * g..(r + 1) * g]
                    .iter()
                    .zip(&t.centre_norms)
                    .enumerate()
                    .map(|(i, (&dot, &n))| (n - 2.0 * dot, i as u32)),
            );
            if self.probes < g {
                order.select_nth_unstable_by(self.probes - 1, |a, b| a.0.total_cmp(&b.0));
            }
            for &(_, grp) in &order[..self.probes] {
                probing[grp as usize].push(r as u32);
            }
        }
        // exact search inside each probed group, for all rows probing it
        let mut best = vec![(f32::INFINITY, 0u32); b];
        let (mut local, mut dist) = (Vec::new(), Vec::new());
        for (grp, who) in probing.iter().enumerate() {
            if who.is_empty() {
                continue;
            }
            let mut buf = Vec::with_capacity(who.len() * dim);
            for &r in who {
                buf.extend_from_slice(&x[r as usize * dim..(r as usize + 1) * dim]);
            }
            let rows = Array2::from_shape_vec((who.len(), dim), buf).expect("rows");
            local.resize(who.len(), 0);
            dist.resize(who.len(), 0.0);
            let (ids, q) = &t.groups[grp];
            q.nearest(rows.view(), &mut local, Some(&mut dist));
            for ((&r, &w), &d) in who.iter().zip(&local).zip(&dist) {
                let slot = &mut best[r as usize];
                let global = ids[w as usize];
                if d < slot.0 || (d == slot.0 && global < slot.1) {
                    *slot = (d, global);
                }
            }
        }
        for (o, (_, w)) in out.iter_mut().zip(best) {
            *o = w;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quantize::naive_nearest;
    use rand::{RngExt, SeedableRng};

    /// Words in 10 tight clusters, each its own group; descriptors near words.
    #[test]
    fn agrees_with_exact_search_and_all_probes_is_exact() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (dim, k, g) = (16, 400, 10);
        let centres: Vec<f32> = (0..g * dim).map(|_| rng.random::<f32>() * 10.0).collect();
        let group_of: Vec<u32> = (0..k as u32).map(|w| w % g as u32).collect();
        let words: Vec<f32> = (0..k)
            .flat_map(|w| {
                let c = &centres[(w % g) * dim..(w % g + 1) * dim];
                c.iter()
                    .map(|v| v + rng.random::<f32>())
                    .collect::<Vec<_>>()
            })
            .collect();
        let tree = TreeQuantizer::new(&words, dim, centres, &group_of);
        let cview = ArrayView2::from_shape((k, dim), &words).unwrap();
        let x = Array2::from_shape_fn((200, dim), |(i, d)| words[(i * 7 % k) * dim + d] + 0.05);
        for probes in [1, g] {
            let mut out = vec![0u32; 200];
            tree.with_probes(probes).quantize(x.view(), &mut out);
            let agree = x
                .rows()
                .into_iter()
                .zip(&out)
                .filter(|(row, w)| naive_nearest(cview, row.as_slice().unwrap()) == **w)
                .count();
            // clusters are well separated: even one probe finds the word
            assert_eq!(agree, 200, "probes {probes}");
        }
    }
}
