//! The ORB pass replayed in the evaluation (`bowloc eval --orb-pass`): every
//! query looked at once per vocabulary by the service's pass
//! ([`crate::pipeline::OrbPass`], with the map's ORB side built beside the
//! cached map), then the full search and each setting asked for run again
//! with the pass first ([`first`]), as the service runs it: a query the pass
//! answers costs its decode, its extraction frame and the pass, and uses no
//! SIFT feature; any other costs the pass on top of the setting's own
//! outcome (its frame is the one SIFT goes on with, so it stays
//! extraction's). Times are the thread's CPU time, the cheapest of
//! [`ROUNDS`], as the cache times extraction, and priced against SIFT over
//! the whole image timed beside them ([`Look::price`]).

use super::summary::{QueryCost, SettingSummary, Stat};
use super::sweep::Outcome;
use super::table::{pct, per_seed, points_lost};
use super::timing::{self, Quantiles};
use crate::dataset::ImageRef;
use crate::features::{self, DecodeLimits, ExtractConfig, Frame, TileGrid};
use crate::orb_pass::{Checked, OrbPassParams};
use crate::pipeline::{OrbPass, extract_interleaved, progress_bar};
use crate::search::rank::distinctness;
use crate::search::{Ranked, StopKind};
use cpu_time::ThreadTime;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashSet;
use std::time::Duration;

/// Times each query's frame and look are taken, the cheapest kept.
pub const ROUNDS: usize = 3;

/// What the pass made of one query on one vocabulary.
#[derive(Debug, Clone, Serialize)]
pub struct Look {
    /// Its answer when it answers: the pick, then the other checked map
    /// images in vote order, each scored by its inliers.
    #[serde(serialize_with = "ids")]
    pub answer: Option<Vec<Ranked>>,
    /// Making the extraction frame from the decoded image, in milliseconds.
    pub frame_ms: f32,
    /// The pass itself (ORB, its words, the votes and the checks), in
    /// milliseconds.
    pub pass_ms: f32,
    /// SIFT over the whole frame, timed beside the look, in milliseconds.
    pub sift_ms: f32,
}

fn ids<S: serde::Serializer>(answer: &Option<Vec<Ranked>>, s: S) -> Result<S::Ok, S::Error> {
    match answer {
        None => s.serialize_none(),
        Some(list) => s.collect_seq(list.iter().map(|r| r.id)),
    }
}

/// The pass's answer scored as the service scores it (each checked image's
/// inliers), with each image's distinctness by inliers
/// ([`distinctness`] against the checked images more than `place_window`
/// map images away).
pub fn ranked(answer: &[u32], checked: &[Checked], place_window: u32) -> Vec<Ranked> {
    let mut leaders: Vec<(f32, u32)> = checked
        .iter()
        .map(|c| (c.inliers as f32, c.image))
        .collect();
    leaders.sort_by(|a, b| b.0.total_cmp(&a.0));
    answer
        .iter()
        .filter_map(|&id| checked.iter().find(|c| c.image == id))
        .map(|c| {
            let score = c.inliers as f32;
            Ranked {
                id: c.image,
                score,
                distinct: distinctness(c.image, score, &leaders, place_window),
            }
        })
        .collect()
}

/// Every query looked at by each vocabulary's pass, one query per core:
/// `looks[seed][query]`. A query that cannot be read or looked at is not
/// answered by the pass and costs it nothing (the search fails it too).
pub fn look_all(
    queries: &[ImageRef],
    extract: &ExtractConfig,
    passes: &[OrbPass],
    place_window: u32,
) -> Vec<Vec<Look>> {
    features::set_opencv_threads(1);
    let bar = progress_bar(queries.len() as u64, "the ORB pass over the queries");
    let per_query: Vec<Vec<Look>> = queries
        .par_iter()
        .map(|q| {
            let looks = look_one(q, extract, passes, place_window).unwrap_or_else(|e| {
                tracing::warn!(query = %q.name, "the ORB pass cannot look at it: {e:#}");
                passes.iter().map(|_| Look::NONE).collect()
            });
            bar.inc(1);
            looks
        })
        .collect();
    bar.finish_and_clear();
    (0..passes.len())
        .map(|s| per_query.iter().map(|q| q[s].clone()).collect())
        .collect()
}

impl Look {
    const NONE: Look = Look {
        answer: None,
        frame_ms: 0.0,
        pass_ms: 0.0,
        sift_ms: 0.0,
    };

    /// Put the look's times in the units of the cache's (`cached_sift_ms`:
    /// the query's SIFT over the whole image as the cache timed it): each
    /// scaled by that over the SIFT timed beside the look. The cache's
    /// times were taken in another sitting, and this machine's speed moves
    /// between sittings; so priced, the pass costs what it costs beside
    /// SIFT, not what the sitting it ran in made it cost.
    pub fn price(&mut self, cached_sift_ms: f32) {
        if self.sift_ms > 0.0 && cached_sift_ms > 0.0 {
            let k = cached_sift_ms / self.sift_ms;
            self.frame_ms *= k;
            self.pass_ms *= k;
            self.sift_ms = cached_sift_ms;
        }
    }
}

/// One query decoded once and looked at by every pass, [`ROUNDS`] times;
/// each round makes the extraction frame once (every pass looks at it) and
/// extracts SIFT over the whole image (its time is what [`Look::price`]
/// scales the pass's by).
fn look_one(
    query: &ImageRef,
    extract: &ExtractConfig,
    passes: &[OrbPass],
    place_window: u32,
) -> anyhow::Result<Vec<Look>> {
    let image = features::decode_file(&query.path, DecodeLimits::default(), extract.max_side)?;
    let (mut sift, mut framed) = (Duration::MAX, Duration::MAX);
    let mut kept: Vec<(Duration, Option<Vec<Ranked>>)> = vec![(Duration::MAX, None); passes.len()];
    for _ in 0..ROUNDS {
        let whole = extract_interleaved(&image, extract, &[TileGrid::WHOLE], 1)?;
        sift = sift.min(whole.first().map_or(Duration::ZERO, |w| w.extract));
        let started = ThreadTime::now();
        let frame = Frame::new(&image, extract)?;
        framed = framed.min(started.elapsed());
        for (pass, (took, answer)) in passes.iter().zip(&mut kept) {
            let looked = ThreadTime::now();
            let look = pass.look(&frame)?;
            *took = (*took).min(looked.elapsed());
            *answer = look
                .answer
                .map(|ids| ranked(&ids, &look.checked, place_window));
        }
    }
    let ms = |d: Duration| (d.as_secs_f64() * 1e3) as f32;
    Ok(kept
        .into_iter()
        .map(|(pass, answer)| Look {
            answer,
            frame_ms: ms(framed),
            pass_ms: ms(pass),
            sift_ms: ms(sift),
        })
        .collect())
}

/// A setting's outcomes `runs[run][query]` with the pass first (`looks`
/// and `costs` per query): where the pass answers, its answer, no feature
/// used and the decode, frame and pass as the request's time; elsewhere the
/// setting's outcome with the pass's time added to its extraction.
pub fn first(runs: &[Vec<Outcome>], looks: &[Look], costs: &[QueryCost]) -> Vec<Vec<Outcome>> {
    runs.iter()
        .map(|run| {
            run.iter()
                .zip(looks)
                .zip(costs)
                .map(|((o, look), cost)| match &look.answer {
                    Some(answer) => Outcome {
                        candidates: answer.clone(),
                        used: 0,
                        total: o.total,
                        stop: StopKind::OrbPass,
                        vote_ms: 0.0,
                        extract_ms: cost.decode_ms as f32 + look.frame_ms + look.pass_ms,
                        verify_ms: 0.0,
                        tiles: 0,
                        verified: true,
                        coarse: false,
                    },
                    None => Outcome {
                        extract_ms: o.extract_ms + look.pass_ms,
                        ..o.clone()
                    },
                })
                .collect()
        })
        .collect()
}

/// One setting with the pass first.
#[derive(Debug, Clone, Serialize)]
pub struct OrbPassRow {
    /// The setting alone: its index in the report's settings.
    pub alone: usize,
    /// The full search it is compared with (verified if it is): its index.
    pub full: usize,
    /// The setting with the pass first, summarized as every setting is.
    pub with: SettingSummary,
}

/// The ORB pass of one evaluation.
#[derive(Debug, Clone, Serialize)]
pub struct OrbPassReport {
    /// The pass's setting, as the service reads it (`[orb_pass]`).
    pub params: OrbPassParams,
    /// Share of the queries the pass answered, per vocabulary seed.
    pub answered: Stat,
    /// Of those, the share whose first candidate is a true match.
    pub right: Stat,
    /// The pass's own time per query (frame and pass), in milliseconds.
    pub pass_ms: Quantiles,
    pub rows: Vec<OrbPassRow>,
    /// What the pass made of each query: `looks[seed][query]`.
    pub looks: Vec<Vec<Look>>,
}

impl OrbPassReport {
    /// The report of `looks` (`[seed][query]`) against the ground truth.
    pub fn new(
        params: OrbPassParams,
        looks: Vec<Vec<Look>>,
        truth: &[HashSet<u32>],
        rows: Vec<OrbPassRow>,
    ) -> Self {
        let share = |f: &dyn Fn(&[Look]) -> f64| {
            Stat::of(&looks.iter().map(|l| vec![f(l)]).collect::<Vec<_>>())
        };
        let answered = share(&|l| {
            l.iter().filter(|l| l.answer.is_some()).count() as f64 / l.len().max(1) as f64
        });
        let right = share(&|l| {
            let (mut n, mut good) = (0, 0);
            for (look, t) in l.iter().zip(truth) {
                if let Some(a) = &look.answer {
                    n += 1;
                    good += usize::from(a.first().is_some_and(|r| t.contains(&r.id)));
                }
            }
            good as f64 / n.max(1) as f64
        });
        let ms: Vec<f64> = looks
            .iter()
            .flatten()
            .map(|l| f64::from(l.frame_ms + l.pass_ms))
            .collect();
        Self {
            params,
            answered,
            right,
            pass_ms: timing::quantiles(&ms),
            rows,
            looks,
        }
    }
}

/// The markdown section of the pass: each setting alone and with the pass
/// first, its recall per vocabulary seed against the full search and
/// against the setting alone, and its request time against the full
/// search's.
pub fn markdown(report: &OrbPassReport, settings: &[SettingSummary]) -> String {
    let p = &report.params;
    let seeds = |s: &Stat| per_seed(s, pct);
    let share = |s: &SettingSummary| {
        let whole = s
            .time_share_whole
            .map_or("–".into(), |w| format!("{:.3}", w.median));
        format!("{:.3} | {whole}", s.time_share.median)
    };
    let mut out = format!(
        "## The ORB pass first\n\n\
         The service's ORB pass (`[orb_pass]`: the top {} ORB-voted map images checked, \
         `{}`; {} binary words; \
         keypoints `{}`) looked at every query before each setting: it answered {} % of \
         the queries (per vocabulary seed {}), {} % of them right (per seed {}), in a \
         median {:.2} ms (p95 {:.2}) of its own (extraction frame and pass, CPU time, \
         cheapest of {ROUNDS}, priced against SIFT over the whole image timed beside it, \
         as the cache timed that SIFT). A query it answers uses no SIFT feature and costs its \
         decode, frame and pass; any other costs the pass besides the setting. `× full \
         search`: the median per-query ratio of the request time to the tiled full \
         search's (`× whole`: to the whole-image full search's, as the service answers \
         `rule=none`); recall in %, each vocabulary seed's mean over runs; `lost`: points \
         under the full search (verified if the setting is) and under the setting alone, \
         per seed.\n\n\
         | setting | % features | × full search | × whole | recall@1, per seed | lost to the full search | lost to the setting alone | recall@5, per seed | lost to the full search | lost to the setting alone |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        p.top,
        p.setting().label(),
        p.words,
        p.grid,
        pct(report.answered.mean),
        seeds(&report.answered),
        pct(report.right.mean),
        seeds(&report.right),
        report.pass_ms.median,
        report.pass_ms.p95,
    );
    for r in &report.rows {
        let (alone, full) = (&settings[r.alone], &settings[r.full]);
        for s in [alone, &r.with] {
            out += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                s.label,
                pct(s.fraction.mean),
                share(s),
                seeds(&s.recall_at_1),
                points_lost(&full.recall_at_1, &s.recall_at_1),
                points_lost(&alone.recall_at_1, &s.recall_at_1),
                seeds(&s.recall_at_5),
                points_lost(&full.recall_at_5, &s.recall_at_5),
                points_lost(&alone.recall_at_5, &s.recall_at_5),
            );
        }
    }
    out.push('\n');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(ids: &[u32], used: u32, extract_ms: f32) -> Outcome {
        Outcome {
            candidates: ids
                .iter()
                .map(|&id| Ranked {
                    id,
                    score: 1.0,
                    distinct: 0.5,
                })
                .collect(),
            used,
            total: 100,
            stop: StopKind::Exhausted,
            vote_ms: 1.0,
            extract_ms,
            verify_ms: 0.5,
            tiles: 4,
            verified: false,
            coarse: false,
        }
    }

    /// A query the pass answers takes its answer, no feature and the
    /// decode, frame and pass as its time; any other keeps its outcome and
    /// pays for the pass.
    #[test]
    fn the_pass_answers_or_adds_its_time() {
        let checked = [
            Checked {
                image: 7,
                inliers: 30,
                scale: Some(1.0),
            },
            Checked {
                image: 20,
                inliers: 10,
                scale: Some(1.1),
            },
            Checked {
                image: 8,
                inliers: 20,
                scale: Some(1.0),
            },
        ];
        let answer = ranked(&[7, 20, 8, 99], &checked, 2);
        assert_eq!(answer.iter().map(|r| r.id).collect::<Vec<_>>(), [7, 20, 8]);
        assert_eq!(answer[0].score, 30.0);
        // 7 against 20, the only image more than 2 away: 30 / 40
        assert!((answer[0].distinct - 0.75).abs() < 1e-6);
        // 20 against 7 and 8: the most is 30
        assert!((answer[1].distinct - 0.25).abs() < 1e-6);
        let looks = [
            Look {
                answer: Some(answer),
                frame_ms: 0.5,
                pass_ms: 4.0,
                sift_ms: 40.0,
            },
            Look {
                answer: None,
                frame_ms: 0.5,
                pass_ms: 3.0,
                sift_ms: 40.0,
            },
        ];
        let cost = QueryCost {
            quantize_ms_per_feature: 0.01,
            decode_ms: 2.0,
        };
        let runs = vec![vec![outcome(&[1, 2], 80, 30.0), outcome(&[3], 60, 20.0)]];
        let with = first(&runs, &looks, &[cost, cost]);
        let (a, b) = (&with[0][0], &with[0][1]);
        assert_eq!(a.candidates[0].id, 7);
        assert_eq!((a.used, a.total, a.tiles), (0, 100, 0));
        assert_eq!(a.stop, StopKind::OrbPass);
        assert!(a.verified);
        assert_eq!((a.extract_ms, a.vote_ms, a.verify_ms), (6.5, 0.0, 0.0));
        assert_eq!(b.candidates, runs[0][1].candidates);
        assert_eq!((b.used, b.extract_ms, b.vote_ms), (60, 23.0, 1.0));
        // priced against a cache that timed SIFT at half this sitting's
        // speed: every time of the look doubles
        let mut slow = looks[0].clone();
        slow.price(80.0);
        assert_eq!(
            (slow.frame_ms, slow.pass_ms, slow.sift_ms),
            (1.0, 8.0, 80.0)
        );
        let mut unknown = looks[1].clone();
        unknown.price(0.0);
        assert_eq!((unknown.pass_ms, unknown.sift_ms), (3.0, 40.0));
    }
}
