//! The compact form of one map feature, kept for voting and verification:
//! its visual word, its Hamming signature and its keypoint, 20 bytes in all.
//!
//! | field | bits | encoding |
//! | --- | --- | --- |
//! | word | 32 | the visual word |
//! | x, y | 16 + 16 | pixels × 4 (quarter-pixel steps, up to 16383.75 px) |
//! | scale | 16 | log2(size) in steps of 1/2048 from 2^-8 (sizes 2^-8 … 2^24) |
//! | angle | 16 | degrees in [0, 360) in steps of 360/65536 |
//! | signature | 64 | where in its word the descriptor lies (`crate::vocabulary::hamming`) |
//!
//! The keypoint's response is not kept: verification does not use it.

use super::Keypoint;

/// Sub-pixel steps per pixel of x and y.
const XY_STEPS: f32 = 4.0;
/// Steps per octave of the log2 scale.
const SCALE_STEPS: f32 = 2048.0;
/// log2 of the smallest size stored.
const SCALE_MIN_LOG2: f32 = -8.0;

/// One map feature: word, packed keypoint and signature.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(C)]
pub struct PackedFeature {
    pub word: u32,
    /// x in the low 16 bits, y in the high 16 bits.
    position: u32,
    /// log-scale code in the low 16 bits, angle code in the high 16 bits.
    shape: u32,
    /// The signature's low and high 32 bits (u32s keep the struct at 4-byte
    /// alignment, without padding).
    signature: [u32; 2],
}

// SAFETY: five u32s, `repr(C)`, no padding; every bit pattern is valid.
unsafe impl bytemuck::Zeroable for PackedFeature {}
// SAFETY: as above.
unsafe impl bytemuck::Pod for PackedFeature {}

/// Bytes per stored feature.
pub const PACKED_BYTES: usize = std::mem::size_of::<PackedFeature>();

fn quantize(value: f32, steps: f32) -> u32 {
    if value.is_finite() {
        (value * steps).round().clamp(0.0, u16::MAX as f32) as u32
    } else {
        0
    }
}

impl PackedFeature {
    /// Pack a feature. Out-of-range values are clamped: coordinates to
    /// [0, 16383.75], sizes to [2^-8, 2^24]; non-finite values become 0.
    pub fn pack(word: u32, signature: u64, k: &Keypoint) -> Self {
        let x = quantize(k.x, XY_STEPS);
        let y = quantize(k.y, XY_STEPS);
        let log_size = if k.size > 0.0 {
            k.size.log2() - SCALE_MIN_LOG2
        } else {
            0.0
        };
        let scale = quantize(log_size, SCALE_STEPS);
        let angle = if k.angle.is_finite() {
            let a = k.angle.rem_euclid(360.0) / 360.0 * 65536.0;
            (a.round() as u32) & 0xffff
        } else {
            0
        };
        Self {
            word,
            position: x | (y << 16),
            shape: scale | (angle << 16),
            signature: [signature as u32, (signature >> 32) as u32],
        }
    }

    /// The Hamming signature.
    #[inline]
    pub fn signature(&self) -> u64 {
        self.signature[0] as u64 | ((self.signature[1] as u64) << 32)
    }

    /// The keypoint back (response 0).
    pub fn keypoint(&self) -> Keypoint {
        let x = (self.position & 0xffff) as f32 / XY_STEPS;
        let y = (self.position >> 16) as f32 / XY_STEPS;
        let size = ((self.shape & 0xffff) as f32 / SCALE_STEPS + SCALE_MIN_LOG2).exp2();
        let angle = (self.shape >> 16) as f32 / 65536.0 * 360.0;
        Keypoint {
            x,
            y,
            size,
            angle,
            response: 0.0,
        }
    }

    /// The position only (what the model fit needs).
    pub fn point(&self) -> [f32; 2] {
        [
            (self.position & 0xffff) as f32 / XY_STEPS,
            (self.position >> 16) as f32 / XY_STEPS,
        ]
    }
}

/// The run of `features` (sorted by word) quantized to `word`.
#[inline]
pub fn word_run(features: &[PackedFeature], word: u32) -> &[PackedFeature] {
    let start = features.partition_point(|f| f.word < word);
    let len = features[start..].partition_point(|f| f.word == word);
    &features[start..start + len]
}

/// Pack one image's features, sorted by word (the order matching and voting
/// expect). `signatures` holds one per word, or is empty (all 0).
pub fn pack_image(words: &[u32], signatures: &[u64], keypoints: &[Keypoint]) -> Vec<PackedFeature> {
    let signature = |i: usize| signatures.get(i).copied().unwrap_or(0);
    let mut packed: Vec<PackedFeature> = words
        .iter()
        .zip(keypoints)
        .enumerate()
        .map(|(i, (&w, k))| PackedFeature::pack(w, signature(i), k))
        .collect();
    packed.sort_by_key(|p| p.word);
    packed
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kp(x: f32, y: f32, size: f32, angle: f32) -> Keypoint {
        Keypoint {
            x,
            y,
            size,
            angle,
            response: 0.5,
        }
    }

    #[test]
    fn round_trip_within_the_quantization_steps() {
        assert_eq!(PACKED_BYTES, 20);
        for k in [
            kp(0.0, 0.0, 1.6, 0.0),
            kp(639.9, 359.3, 31.7, 359.9),
            kp(12.125, 480.0, 2.3, 181.4),
            kp(5000.3, 1.1, 150.0, 90.0),
        ] {
            let p = PackedFeature::pack(42, 0xdead_beef_0123_4567, &k);
            let back = p.keypoint();
            assert_eq!(p.word, 42);
            assert_eq!(p.signature(), 0xdead_beef_0123_4567);
            assert!((back.x - k.x).abs() <= 0.125, "{k:?} → {back:?}");
            assert!((back.y - k.y).abs() <= 0.125, "{k:?} → {back:?}");
            assert!((back.size / k.size - 1.0).abs() < 4e-4, "{k:?} → {back:?}");
            let da = (back.angle - k.angle).rem_euclid(360.0);
            assert!(da.min(360.0 - da) <= 360.0 / 65536.0, "{k:?} → {back:?}");
            assert_eq!(p.point(), [back.x, back.y]);
        }
    }

    #[test]
    fn out_of_range_values_are_clamped_not_wrapped() {
        let back = PackedFeature::pack(1, 0, &kp(-3.0, 1e9, 0.0, f32::NAN)).keypoint();
        assert_eq!(back.x, 0.0);
        assert_eq!(back.y, 16383.75);
        assert_eq!(back.angle, 0.0);
        assert!(back.size > 0.0 && back.size < 0.01);
        let back = PackedFeature::pack(1, 0, &kp(1.0, 1.0, 4.0, -90.0)).keypoint();
        assert!((back.angle - 270.0).abs() < 0.01);
    }

    #[test]
    fn images_are_packed_sorted_by_word() {
        let k = kp(1.0, 2.0, 3.0, 4.0);
        let packed = pack_image(&[5, 1, 3, 1], &[50, 10, 30, 11], &[k, k, k, k]);
        let words: Vec<u32> = packed.iter().map(|p| p.word).collect();
        assert_eq!(words, vec![1, 1, 3, 5]);
        let signatures: Vec<u64> = packed.iter().map(|p| p.signature()).collect();
        assert_eq!(signatures, vec![10, 11, 30, 50]);
        assert!(pack_image(&[], &[], &[]).is_empty());
        assert_eq!(word_run(&packed, 1).len(), 2);
        assert_eq!(word_run(&packed, 5)[0].signature(), 50);
        assert!(word_run(&packed, 2).is_empty());
        assert!(word_run(&packed, 9).is_empty());
    }
}
