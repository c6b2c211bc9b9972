//! The search over a map split into shards by image, as a fleet would run a
//! map whose postings outgrow one machine. Each shard holds the postings of
//! its own images (every word, with the whole map's idf and weights, so its
//! votes are the whole map's votes for those images). A coordinator holds
//! the vocabulary: it quantizes the query, sends each block of words to every
//! shard, and each shard votes the block and answers with its statistics
//! after every feature of it ([`Report`]). The coordinator merges the
//! shards' statistics ([`Merged`], a [`VoteStats`] like the voter) and replays
//! the rule feature by feature, so it stops at the same feature as one
//! machine holding the whole map, and ranks the same candidates with the
//! same scores, with one round trip per block instead of one per feature.
//!
//! Here the shards are in-process partitions of a real map and the messages
//! are counted ([`Traffic`]), not sent; docs/scale.md gives the design and
//! what the evaluation's simulation (`bowloc shards`) measured. Geometric
//! rules (`verified`) are not covered: their check needs the leader's stored
//! features, which live on its shard.

use super::rank::Ranked;
use super::stop::{RuleContext, StopRule};
use super::vote::{Needs, Tally, VoteStats, Voter};
use super::{
    KnownFeatures, SearchOptions, SearchOutcome, SearchTimings, StopInfo, StopKind, batch_order,
};
use crate::index::{MapIndex, MapView, Postings, StringTable};
use serde::Serialize;

/// The shard that holds map image `j`: image j lives on shard j mod S as its
/// local image j / S, so ids keep their order inside a shard and ties break
/// as on one machine.
pub fn shard_of(j: u32, shards: usize) -> usize {
    j as usize % shards.max(1)
}

/// One shard's part of a map: the postings of its images, by local id.
struct Shard {
    offsets: Vec<u64>,
    images: Vec<u32>,
    weights: Vec<f32>,
    image_max: Vec<f32>,
    /// The shard keeps no names (the coordinator answers with ids).
    names: StringTable,
}

impl Shard {
    fn view<'a>(&'a self, idf: &'a [f32]) -> MapView<'a> {
        MapView {
            idf,
            postings: Postings::new(&self.offsets, &self.images, &self.weights),
            image_max: &self.image_max,
            names: self.names.as_view(),
            places: self.names.as_view(),
            poses: &[],
            geometry_offsets: &[],
            geometry: &[],
            feature_runs: &[],
            overlay: None,
        }
    }
}

/// A map split into shards by image.
pub struct ShardedMap<'m> {
    idf: &'m [f32],
    /// Every image's cap (the coordinator's copy: 4 bytes an image).
    image_max: &'m [f32],
    vote_cap: f32,
    shards: Vec<Shard>,
}

impl<'m> ShardedMap<'m> {
    /// Split `map` into `count` shards (at least 1), read through its public view.
    pub fn split(map: &'m MapIndex, count: usize) -> Self {
        let count = count.max(1);
        let v = map.view();
        let mut shards: Vec<Shard> = (0..count)
            .map(|s| Shard {
                offsets: vec![0],
                images: Vec::new(),
                weights: Vec::new(),
                image_max: v.image_max.iter().skip(s).step_by(count).copied().collect(),
                names: StringTable::from_strings(std::iter::empty::<&str>()),
            })
            .collect();
        for w in 0..v.postings.words() as u32 {
            let (ids, weights) = v.postings.list(w);
            for (&j, &d) in ids.iter().zip(weights) {
                let shard = &mut shards[shard_of(j, count)];
                shard.images.push(j / count as u32);
                shard.weights.push(d);
            }
            for shard in &mut shards {
                shard.offsets.push(shard.images.len() as u64);
            }
        }
        Self {
            idf: v.idf,
            image_max: v.image_max,
            vote_cap: v.image_max.iter().copied().fold(0.0, f32::max),
            shards,
        }
    }

    /// Number of shards.
    pub fn shards(&self) -> usize {
        self.shards.len()
    }

    /// (word, image) entries each shard holds.
    pub fn postings_per_shard(&self) -> Vec<usize> {
        self.shards.iter().map(|s| s.images.len()).collect()
    }
}

/// What one shard reports after one feature, image ids global.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// Its leading images, best first (h, id).
    pub top: Vec<(f32, u32)>,
    /// Σ h over its images.
    pub sum: f64,
    /// Σ v² of each of its leading images, in `top`'s order (with
    /// `Needs::squares`).
    pub top_squares: Vec<f32>,
    /// The largest Σ v² of its images other than its leader, and of all its
    /// images (with `Needs::squares`).
    pub squares: [f32; 2],
    /// `best_outside(k, left)` over its images for k = 0, 1, … (with
    /// `Needs::outside`, once N is known).
    pub outside: Vec<f32>,
}

impl Report {
    fn of(voter: &Voter<'_>, needs: Needs, shards: usize, shard: usize) -> Self {
        let global = |j: u32| j * shards as u32 + shard as u32;
        let top: Vec<(f32, u32)> = voter.top().iter().map(|&(h, j)| (h, global(j))).collect();
        let leader = voter.top().first().map(|e| e.1);
        let squares = match (needs.squares, leader) {
            (true, Some(l)) => [
                voter.max_squares_except(l),
                voter.max_squares_except(u32::MAX),
            ],
            _ => [0.0; 2],
        };
        let top_squares = if needs.squares {
            voter
                .top()
                .iter()
                .map(|&(_, j)| voter.squares_of(j))
                .collect()
        } else {
            Vec::new()
        };
        let outside = match (needs.outside, voter.tally().remaining()) {
            (true, Some(left)) => voter.best_outside_each(needs.top, left as f32),
            _ => Vec::new(),
        };
        Self {
            top,
            sum: voter.tally().sum,
            top_squares,
            squares,
            outside,
        }
    }

    /// Bytes of the report in a packed encoding: 8 per (h, id) entry, 8 for
    /// the sum, 4 per other number.
    fn bytes(&self, needs: Needs) -> usize {
        8 * self.top.len()
            + 8
            + if needs.squares {
                8 + 4 * self.top.len()
            } else {
                0
            }
            + 4 * self.outside.len()
    }
}

/// The statistics of the whole map, merged from the shards' reports at one
/// feature: what the coordinator's rule reads.
pub struct Merged<'a> {
    tally: Tally,
    /// The shards' leading images merged, best first.
    ranked: Vec<(f32, u32)>,
    /// Entries [`VoteStats::top`] shows (as one machine's voter keeps).
    keep: usize,
    reports: Vec<Report>,
    image_max: &'a [f32],
}

impl Merged<'_> {
    fn merge(&mut self, reports: &[Report]) {
        self.ranked.clear();
        for r in reports {
            self.ranked.extend_from_slice(&r.top);
        }
        self.ranked
            .sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        self.tally.sum = reports.iter().map(|r| r.sum).sum();
        if let Some(&(max, leader)) = self.ranked.first() {
            self.tally.leader = Some(leader);
            self.tally.max = max;
            self.tally.second = self.ranked.get(1).map_or(0.0, |e| e.0);
        }
        self.reports.clone_from_slice(reports);
    }

    fn shards(&self) -> usize {
        self.reports.len()
    }

    /// The top `n` by h (ties by lower id), scores h/t, as [`super::rank::top_n`];
    /// distinctness against the images the shards reported.
    fn top_n(&self, n: usize, min_score: f32, window: u32) -> Vec<Ranked> {
        if self.tally.features == 0 {
            return Vec::new();
        }
        let scale = 1.0 / self.tally.features as f32;
        self.ranked
            .iter()
            .take(n)
            .map(|&(h, id)| Ranked {
                id,
                score: h * scale,
                distinct: super::rank::distinctness(id, h, &self.ranked, window),
            })
            .filter(|r| r.score >= min_score)
            .collect()
    }
}

impl VoteStats for Merged<'_> {
    fn tally(&self) -> &Tally {
        &self.tally
    }

    fn top(&self) -> &[(f32, u32)] {
        &self.ranked[..self.keep.min(self.ranked.len())]
    }

    /// Known for each image in its shard's leaders, so for every image of
    /// [`top`](VoteStats::top): the images a rule asks about. Other images
    /// answer 0.
    fn squares_of(&self, j: u32) -> f32 {
        let r = &self.reports[shard_of(j, self.shards())];
        r.top
            .iter()
            .position(|e| e.1 == j)
            .and_then(|i| r.top_squares.get(i).copied())
            .unwrap_or(0.0)
    }

    /// Exact when `j` is a shard's leader (the overall leader is).
    fn max_squares_except(&self, j: u32) -> f32 {
        self.reports
            .iter()
            .map(|r| {
                if r.top.first().map(|e| e.1) == Some(j) {
                    r.squares[0]
                } else {
                    r.squares[1]
                }
            })
            .fold(0.0, f32::max)
    }

    fn image_vote_cap(&self, j: u32) -> f32 {
        self.image_max.get(j as usize).copied().unwrap_or(0.0)
    }

    /// The images outside the overall top n are, on each shard, those
    /// outside its own first k (its share of the top n), so each shard's
    /// report for its k answers for it. `left` is the shards' own (N − t).
    fn best_outside(&self, n: usize, _left: f32) -> f32 {
        let leaders = &self.ranked[..n.min(self.ranked.len())];
        let shards = self.shards();
        self.reports
            .iter()
            .enumerate()
            .map(|(s, r)| {
                let k = leaders
                    .iter()
                    .filter(|e| shard_of(e.1, shards) == s)
                    .count();
                r.outside.get(k).copied().unwrap_or(f32::INFINITY)
            })
            .fold(0.0, f32::max)
    }
}

/// The messages a sharded search exchanged.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Traffic {
    /// Round trips from the coordinator to every shard in parallel: one per
    /// block of words voted.
    pub rounds: usize,
    /// Messages both ways: 2 × shards × rounds.
    pub messages: usize,
    /// Bytes of those messages' contents (4 a word to the shards; the
    /// reports back, `Report::bytes`), framing not counted.
    pub bytes: usize,
    /// Messages a round trip per feature would take: 2 × shards × features voted.
    pub per_feature_messages: usize,
}

/// The answer of a sharded search and what it cost in messages.
pub struct ShardedOutcome {
    pub outcome: SearchOutcome,
    pub traffic: Traffic,
}

/// [`super::search_tiles`] over a sharded map, for words known in advance:
/// tiles in extraction order with the image share each one covers, each
/// tile's features in the order one machine would vote them, blocks of
/// `options.block` words sent to every shard. The shards hold postings only,
/// not the map's features, so votes are plain tf-idf: signatures are not
/// read, and the one-machine search it matches has `hamming: None`.
pub fn search_tiles(
    map: &ShardedMap<'_>,
    tiles: &[(KnownFeatures<'_>, f64)],
    options: &SearchOptions,
) -> ShardedOutcome {
    let shards = map.shards();
    let mut rule: Box<dyn StopRule> = options.rule.build(&RuleContext {
        top_n: options.top_n,
        prior: None,
        place_window: options.place_window,
    });
    let needs = rule.needs();
    // what the shards keep: what the rule reads, and the answer's top n
    let shard_needs = Needs {
        top: needs.top.max(2).max(options.top_n),
        ..needs
    };
    let mut voters: Vec<Voter<'_>> = map
        .shards
        .iter()
        .map(|s| {
            let mut v = Voter::with_needs(&s.view(map.idf), shard_needs);
            v.set_vote_cap(map.vote_cap);
            v
        })
        .collect();
    let mut merged = Merged {
        tally: Tally {
            images: map.image_max.len(),
            vote_cap: map.vote_cap,
            ..Tally::default()
        },
        ranked: Vec::new(),
        keep: needs.top.max(2),
        reports: vec![Report::default(); shards],
        image_max: map.image_max,
    };
    let mut traffic = Traffic::default();
    let mut stop = None;
    let mut fed = 0usize;
    let block = options.block.max(1);
    let mut reports: Vec<Vec<Report>> = Vec::new();
    let mut share = 0.0;
    // a rule that fires inside a tile of several stops at the tile's end
    // ([`super::Search::feed_tile`])
    let streamed = tiles.len() > 1 && options.finish_tile;
    let mut finishing = None;
    'tiles: for (k, &(features, area)) in tiles.iter().enumerate() {
        let words = features.words;
        fed += words.len();
        share += area;
        if k + 1 == tiles.len() {
            merged.tally.total = Some(fed);
            merged.tally.expected_total = Some(fed as f64);
            for v in &mut voters {
                v.set_total(fed);
            }
        } else if merged.tally.total.is_none() {
            merged.tally.expected_total = Some(fed as f64 / share.max(1e-9));
        }
        let order = batch_order(options, words.len(), k as u64);
        for indices in order.chunks(block) {
            // one round: the block to every shard, each shard's reports back
            traffic.rounds += 1;
            traffic.messages += 2 * shards;
            traffic.bytes += shards * (8 + 4 * indices.len());
            reports.clear();
            for &i in indices {
                let w = words[i as usize];
                reports.push(
                    voters
                        .iter_mut()
                        .enumerate()
                        .map(|(s, v)| {
                            v.vote(w, 0);
                            Report::of(v, shard_needs, shards, s)
                        })
                        .collect(),
                );
            }
            traffic.bytes += reports
                .iter()
                .flatten()
                .map(|r| r.bytes(needs))
                .sum::<usize>();
            // the coordinator replays the rule on the merged statistics
            for feature in &reports {
                merged.tally.features += 1;
                merged.merge(feature);
                if merged.tally.features < options.min_features || finishing.is_some() {
                    continue;
                }
                if let Some(why) = rule.check(&merged) {
                    if streamed && merged.tally.features < fed {
                        finishing = Some(why);
                    } else {
                        stop = Some((StopKind::Rule, why));
                        break 'tiles;
                    }
                }
            }
        }
        if let Some(why) = finishing.take() {
            stop = Some((StopKind::Rule, super::tile_finished(why)));
            break;
        }
    }
    let used = merged.tally.features;
    traffic.per_feature_messages = 2 * shards * used;
    let (kind, detail) =
        stop.unwrap_or_else(|| (StopKind::Exhausted, "all features used".to_owned()));
    ShardedOutcome {
        outcome: SearchOutcome {
            candidates: merged.top_n(options.top_n, options.min_score, options.place_window),
            features_total: fed,
            features_used: used,
            stop: StopInfo {
                kind,
                at_feature: used,
                detail,
            },
            timings: SearchTimings::default(),
            // the sharded search records no race
            trace: None,
            posterior: None,
            frame_posterior: None,
        },
        traffic,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::synthetic::zipf_map;
    use crate::search::stop::RULES;
    use crate::search::{KnownFeatures, RuleSpec, search_tiles as one_machine};

    /// On a synthetic map, every vote-only rule stops at the same feature
    /// and ranks the same candidates with the same scores on 1, 2, 3 and 8
    /// shards as on one machine, over tiled queries and many orders; and the
    /// messages are one round trip per block.
    #[test]
    fn shards_answer_as_one_machine() {
        let map = zipf_map(120, 400, 60, 7);
        let words = map.image_words();
        let mut stopped_early = 0;
        for count in [1, 2, 3, 8] {
            let sharded = ShardedMap::split(&map, count);
            assert_eq!(
                sharded.postings_per_shard().iter().sum::<usize>(),
                map.view().postings.len()
            );
            for info in RULES.iter().filter(|r| r.shardable()) {
                let rule = RuleSpec::new(info.name, info.parameter.map(|p| p.example)).unwrap();
                for q in 0..12u64 {
                    // a map image's words, with another's mixed in, as four tiles
                    let mut query = words[q as usize * 7 % 120].clone();
                    query.extend_from_slice(&words[(q as usize * 13 + 5) % 120][..20]);
                    let quarter = query.len().div_ceil(4);
                    let tiles: Vec<(KnownFeatures<'_>, f64)> = query
                        .chunks(quarter)
                        .map(|c| (KnownFeatures::words(c), 0.25))
                        .collect();
                    for min_features in [0, 30] {
                        let options = SearchOptions {
                            rule: rule.clone(),
                            top_n: 3,
                            seed: q,
                            block: 8,
                            min_features,
                            hamming: None,
                            ..SearchOptions::default()
                        };
                        let (one, _, _) = one_machine(&map, &tiles, &options, false, None);
                        let s = search_tiles(&sharded, &tiles, &options);
                        let o = &s.outcome;
                        assert_eq!(o.candidates, one.candidates, "{rule} on {count} shards");
                        assert_eq!(o.stop, one.stop, "{rule} on {count} shards");
                        assert_eq!(o.features_total, one.features_total);
                        if one.features_used < query.len() {
                            stopped_early += 1;
                        }
                        let blocks: usize = tiles[..]
                            .iter()
                            .scan(0, |fed, t| {
                                let before = *fed;
                                *fed += t.0.len();
                                Some((before, t.0.len()))
                            })
                            .filter(|&(before, _)| before < o.features_used)
                            .map(|(before, len)| (o.features_used - before).min(len).div_ceil(8))
                            .sum();
                        assert_eq!(s.traffic.rounds, blocks);
                        assert_eq!(s.traffic.messages, 2 * count * blocks);
                        assert_eq!(s.traffic.per_feature_messages, 2 * count * o.features_used);
                    }
                }
            }
        }
        assert!(
            stopped_early > 100,
            "the rules stop early in {stopped_early} searches"
        );
    }
}
