//! Arbitrary bytes as an uploaded image: decoding (grey for the search, at
//! its size and shrunk for a small frame, and colour for a thumbnail), then
//! extraction whole and in streamed tiles with the coarse pass, and ORB as
//! the ORB pass runs it (its own corners, and spread over a grid), must give
//! a value or an error: never a panic, nor a crash in the decoders OpenCV
//! links (libjpeg, libpng, libtiff, libwebp, and its own BMP and PNM readers)
//! or in SIFT or ORB on whatever pixels they return.
#![no_main]

use bowloc::features::orb::OrbDetector;
use bowloc::orb_pass::ORB_KEYPOINTS;
use bowloc::features::{
    DecodeLimits, ExtractConfig, Frame, TileGrid, Tiles, decode, extract, probe, thumbnail,
};
use bowloc::search::TileOrder;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // small images only: the budget goes to many inputs, not to large ones
    let limits = DecodeLimits {
        max_pixels: 1 << 18,
    };
    let probed = probe(data, limits);
    let _ = thumbnail(data, 16, limits);
    let config = ExtractConfig {
        max_side: 64,
        ..ExtractConfig::default()
    };
    let grid: TileGrid = "2x2+8,coarse".parse().unwrap();
    for frame_side in [0, config.max_side] {
        let decoded = decode(data, limits, frame_side);
        // decoding refuses everything the header check refuses
        assert!(probed.is_ok() || decoded.is_err());
        let Ok(image) = decoded else { continue };
        let _ = extract(&image, &config);
        if let Ok(mut tiles) = Tiles::new(&image, &config, grid, Some((TileOrder::Richest, 7))) {
            while tiles.next_tile().is_some() {}
        }
        // a frame large enough for ORB to find corners in
        let orb_config = ExtractConfig {
            max_side: 128,
            ..ExtractConfig::default()
        };
        if let Ok(frame) = Frame::new(&image, &orb_config) {
            for grid in [None, Some((2, 2))] {
                if let Ok(mut orb) = OrbDetector::new(ORB_KEYPOINTS, grid) {
                    let _ = orb.detect(&frame);
                }
            }
        }
    }
});
