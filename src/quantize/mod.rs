//! Quantization: each descriptor → the id of its nearest visual word. The
//! expensive step of bag-of-words search, so it is batched: descriptors come in
//! small blocks and distances to all centroids are one matrix multiply.
//! [`ExactQuantizer`] finds the true nearest word; [`TreeQuantizer`] searches
//! only the words near a descriptor, for vocabularies of 50 000 words and more.

mod exact;
mod kernels;
mod tree;

pub use exact::{ExactQuantizer, squared_norms};
pub use kernels::Kernel;
pub use tree::{TreeQuantizer, TreeSearch};

use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};

/// Which quantizer a query uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind", deny_unknown_fields)]
pub enum QuantizerKind {
    /// The exact nearest word.
    #[default]
    Exact,
    /// The two-level tree, searching `probes` groups per descriptor.
    Tree { probes: usize },
}

/// Maps descriptor rows to visual-word ids.
pub trait Quantizer: Send + Sync {
    /// Number of words (centroids).
    fn words(&self) -> usize;
    /// Descriptor dimension.
    fn dim(&self) -> usize;
    /// Write the nearest word of each row of `block` into `out[..block.nrows()]`.
    fn quantize(&self, block: ArrayView2<'_, f32>, out: &mut [u32]);
}

impl<Q: Quantizer + ?Sized> Quantizer for &Q {
    fn words(&self) -> usize {
        (**self).words()
    }
    fn dim(&self) -> usize {
        (**self).dim()
    }
    fn quantize(&self, block: ArrayView2<'_, f32>, out: &mut [u32]) {
        (**self).quantize(block, out)
    }
}

/// Nearest word by exhaustive search, one descriptor at a time: the reference
/// the fast kernels are tested against.
pub fn naive_nearest(centroids: ArrayView2<'_, f32>, x: &[f32]) -> u32 {
    let mut best = (f32::INFINITY, 0u32);
    for (k, c) in centroids.rows().into_iter().enumerate() {
        let d: f32 = c.iter().zip(x).map(|(a, b)| (a - b) * (a - b)).sum();
        if d < best.0 {
            best = (d, k as u32);
        }
    }
    best.1
}
