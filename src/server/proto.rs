//! The protobuf form of the answer, for clients that send
//! `Accept: application/x-protobuf`: the types prost generates at build time
//! from `proto/localize.proto`, and the conversion from
//! [`report::Localization`](crate::report::Localization).

use crate::report::{Candidate, Localization, RacePoint, RaceTrace, SequenceAnswer};
use crate::search::StopInfo;

/// Generated from `proto/localize.proto` (package `bowloc.v1`).
pub mod pb {
    include!(concat!(env!("OUT_DIR"), "/bowloc.v1.rs"));
}

/// Media type of protobuf answers.
pub const CONTENT_TYPE: &str = "application/x-protobuf";

impl From<&Localization> for pb::Localization {
    fn from(a: &Localization) -> Self {
        Self {
            candidates: a.candidates.iter().map(candidate).collect(),
            features: Some(pb::FeatureUse {
                total: a.features.total as u64,
                used: a.features.used as u64,
                fraction: a.features.fraction,
                extracted: a.features.extracted as u64,
            }),
            tiles: Some(pb::TileUse {
                extracted: a.tiles.extracted as u32,
                total: a.tiles.total as u32,
                grid: a.tiles.grid.to_string(),
                order: a.tiles.order.to_string(),
                saved_ms: a.tiles.saved_ms,
            }),
            rule: Some(pb::Rule {
                name: a.rule.name.clone(),
                parameter: a.rule.parameter.map(str::to_owned),
                value: a.rule.value,
                or_verified: a.rule.or_verified,
            }),
            stop: Some(stop(&a.stop)),
            seed: a.seed,
            image: Some(pb::ImageSize {
                width: a.image.width,
                height: a.image.height,
            }),
            timings_ms: Some(pb::Timings {
                decode: a.timings_ms.decode,
                extract: a.timings_ms.extract,
                quantize: a.timings_ms.quantize,
                vote: a.timings_ms.vote,
                verify: a.timings_ms.verify,
                orb_pass: a.timings_ms.orb_pass,
                total: a.timings_ms.total,
            }),
            map: Some(pb::MapIdentity {
                name: a.map.name.clone(),
                images: a.map.images as u64,
                words: a.map.words as u64,
                vocabulary: a.map.vocabulary.clone(),
            }),
            verified: a.verified,
            trace: a.trace.as_ref().map(trace),
            sequence: a.sequence.as_ref().map(sequence),
            orb_pass: a.orb_pass.map(|u| pb::OrbPassUse {
                answered: u.answered,
                checked: u.checked as u32,
            }),
        }
    }
}

fn sequence(s: &SequenceAnswer) -> pb::SequenceAnswer {
    pb::SequenceAnswer {
        name: s.name.clone(),
        frame: s.frame,
        frames: s.frames,
        restart: s.restart.map(str::to_owned),
        candidates: s
            .candidates
            .iter()
            .map(|c| pb::FilteredCandidate {
                rank: c.rank as u32,
                id: c.id,
                name: c.name.clone(),
                probability: c.probability,
            })
            .collect(),
    }
}

fn candidate(c: &Candidate) -> pb::Candidate {
    pb::Candidate {
        rank: c.rank as u32,
        id: c.id,
        name: c.name.clone(),
        score: c.score,
        distinct: c.distinct,
        votes: c.votes,
        inliers: c.inliers,
        verified: c.verified,
        scale: c.scale,
        place: c.place.clone(),
        pose: c.pose.clone().unwrap_or_default(),
        probability: c.probability,
    }
}

fn stop(s: &StopInfo) -> pb::Stop {
    pb::Stop {
        kind: s.kind.name().to_owned(),
        at_feature: s.at_feature as u64,
        detail: s.detail.clone(),
    }
}

fn points(points: &[RacePoint]) -> Vec<pb::RacePoint> {
    points
        .iter()
        .map(|p| pb::RacePoint {
            features: p.features,
            leader: p.leader,
            leader_votes: p.leader_votes,
            runner_up_votes: p.runner_up_votes,
            mean_votes: p.mean_votes,
            statistic: p.statistic,
            threshold: p.threshold,
        })
        .collect()
}

fn trace(t: &RaceTrace) -> pb::Trace {
    pb::Trace {
        every: t.every,
        points: points(&t.points),
        tile_ends: t.tile_ends.clone(),
        warm_up: t.warm_up,
        full: t.full.as_ref().map(|f| pb::FullRace {
            features: f.features as u64,
            stop: Some(stop(&f.stop)),
            every: f.every,
            points: points(&f.points),
            candidates: f.candidates.iter().map(candidate).collect(),
        }),
        frame_side: t.frame_side,
        matches: t
            .matches
            .iter()
            .map(|m| pb::CandidateMatches {
                id: m.id,
                lines: m
                    .lines
                    .iter()
                    .map(|&[query_x, query_y, map_x, map_y]| pb::MatchLine {
                        query_x,
                        query_y,
                        map_x,
                        map_y,
                    })
                    .collect(),
            })
            .collect(),
    }
}

/// Encode an answer.
pub fn encode(answer: &Localization) -> Vec<u8> {
    prost::Message::encode_to_vec(&pb::Localization::from(answer))
}

#[cfg(test)]
mod tests {
    use crate::search::StopKind;

    #[test]
    fn stop_kinds_are_spelled_as_in_json() {
        for kind in StopKind::ALL {
            assert_eq!(serde_json::to_value(kind).unwrap(), kind.name());
        }
    }
}
