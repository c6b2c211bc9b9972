//! How much the learned coarse-pass plan (`--tiles …,auto`) depends on the
//! order its queries come in. The sweep replays one plan over the dataset's
//! order, as a server sent the queries in turn would learn it; here fresh
//! plans, each a server just started, see the queries as many times as the
//! sweep has runs, each time in a random order of their own (`--plan-orders
//! N`), and each order reports the share of its
//! searches started with the coarse pass, the plan it settled on, its median
//! request time against the whole-image full search's, and its recall@1.
//! The same orders are also replayed on restarted servers
//! ([`Start::Restarted`]): each goes on from the plan a server kept after
//! seeing the queries as often in another random order, as the service
//! does with `search.remember_plan`.

use super::metrics;
use super::summary::{answers, stage_sample};
use super::sweep::{self, LearnedPlan, Outcome, Ranking, Setting};
use super::timing::median;
use crate::features::CoarseChoice;
use crate::index::MapIndex;
use crate::search::permute::permutation;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashSet;

/// Salt of the query orders' seeds, apart from the feature orders'.
const ORDER_SALT: u64 = 0x7175_6572_7920_6f72;

/// One fresh plan over the queries in one order.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct OrderReplay {
    /// Share of the searches started with the coarse pass.
    pub started_coarse: f64,
    /// The plan preferred after the last query: with the coarse pass or not
    /// (`None`: still in its trials).
    pub settled_coarse: Option<bool>,
    /// Median request time (every stage, decoding included), ms.
    pub median_ms: f64,
    /// Mean over the passes.
    pub recall_at_1: f64,
}

/// How each order's plan starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Start {
    /// A server just started for the first time: the plan runs its trials.
    Fresh,
    /// A server restarted: the plan goes on from what another served its
    /// passes over the queries in another random order learned.
    Restarted,
}

impl Start {
    pub const BOTH: [Start; 2] = [Start::Fresh, Start::Restarted];

    pub fn name(self) -> &'static str {
        match self {
            Start::Fresh => "fresh",
            Start::Restarted => "restarted",
        }
    }
}

/// A setting's replays over query orders on one vocabulary.
#[derive(Debug, Clone, Serialize)]
pub struct PlanOrders {
    pub label: String,
    pub start: Start,
    /// The vocabulary's k-means seed.
    pub seed: u64,
    /// Median request time of the whole-image full search (every run and
    /// query), ms: what `median_ms` is compared with.
    pub full_median_ms: f64,
    /// Passes over the queries each order made.
    pub passes: u32,
    pub orders: Vec<OrderReplay>,
}

impl PlanOrders {
    /// Orders whose plan preferred the coarse pass after the last query.
    pub fn settled_coarse(&self) -> usize {
        let settled = self
            .orders
            .iter()
            .filter(|o| o.settled_coarse == Some(true));
        settled.count()
    }

    /// A figure of every order: its min, median and max over the orders.
    pub fn spread(&self, figure: impl Fn(&OrderReplay) -> f64) -> [f64; 3] {
        let v: Vec<f64> = self.orders.iter().map(figure).collect();
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        [lo, median(&v), hi]
    }

    /// Each order's median request against the whole-image full search's.
    pub fn ratio(&self, o: &OrderReplay) -> f64 {
        o.median_ms / self.full_median_ms
    }
}

/// What a learned search in the service's configuration needs to replay.
#[derive(Clone, Copy)]
pub struct Replayed<'a> {
    pub map: &'a MapIndex,
    pub plan: LearnedPlan<'a>,
    pub setting: &'a Setting,
    pub truth: &'a [HashSet<u32>],
    pub ranking: Ranking,
}

/// Replay `orders` plans of `setting` started as `start` says, each over
/// `passes` passes of the queries, every pass in a random order of its own
/// (the sweep's runs, shuffled); pass p of order k draws the feature orders
/// of the sweep's run k·passes + p. A restarted plan first learns from
/// `passes` passes in the orders of runs past the replayed ones. Request
/// times and recall@1 are over the replayed searches.
pub fn replay(r: Replayed<'_>, start: Start, orders: u32, passes: u32) -> Vec<OrderReplay> {
    (0..orders)
        .into_par_iter()
        .map(|k| {
            let choice = CoarseChoice::default();
            if start == Start::Restarted {
                let before = CoarseChoice::default();
                serve(r, &before, (orders + k) * passes, passes);
                choice
                    .resume(before.learned())
                    .expect("a plan's own figures are a plan's");
            }
            let (ms, started, recall) = serve(r, &choice, k * passes, passes);
            OrderReplay {
                started_coarse: started as f64 / ms.len().max(1) as f64,
                settled_coarse: choice.preferred(),
                median_ms: median(&ms),
                recall_at_1: metrics::mean(&recall),
            }
        })
        .collect()
}

/// `passes` passes of the queries with `choice`, pass p in the order of run
/// `first_run` + p: every request's time, how many started with the coarse
/// pass, and each pass's recall@1.
fn serve(
    r: Replayed<'_>,
    choice: &CoarseChoice,
    first_run: u32,
    passes: u32,
) -> (Vec<f64>, usize, Vec<f64>) {
    let n = r.plan.plain.0.len();
    let mut ms = Vec::with_capacity(n * passes as usize);
    let mut started = 0;
    let mut recall = Vec::with_capacity(passes as usize);
    for run in first_run..first_run + passes {
        let mut outcomes: Vec<Option<Outcome>> = vec![None; n];
        for q in permutation(n, ORDER_SALT ^ u64::from(run)) {
            let q = q as usize;
            let at = sweep::seed(run, q);
            let o = sweep::learned_search(r.map, r.plan, r.setting, Some(choice), q, at, r.ranking);
            ms.push(stage_sample(&o, r.plan.cost(&o, q)).total());
            started += usize::from(o.coarse);
            outcomes[q] = Some(o);
        }
        let outcomes: Vec<Outcome> = outcomes.into_iter().flatten().collect();
        recall.push(metrics::recall_at(&answers(&outcomes, r.truth), 1));
    }
    (ms, started, recall)
}

/// The `results.md` section: one row per setting and vocabulary seed.
pub fn markdown(rows: &[PlanOrders]) -> String {
    let Some(first) = rows.first() else {
        return String::new();
    };
    let mut out = format!(
        "\n## The learned plan over query orders\n\n\
         Each order is a plan that sees every query \
         once in each of {} passes, every pass in a random order of its own ({} \
         orders a seed): on a `fresh` server (just started: the plan runs its \
         trials) or a `restarted` one (the plan goes on from what a server kept \
         after as many passes in another random order). `settled coarse`: \
         orders whose plan preferred the coarse pass after the last query; `started \
         coarse` and `× full search` (its median request against the whole-image full \
         search's median): min / median / max over the orders.\n\n\
         | setting | seed | server | settled coarse | started coarse | × full search | recall@1 |\n\
         | --- | --- | --- | --- | --- | --- | --- |\n",
        first.passes,
        first.orders.len()
    );
    let pct = |v: f64| format!("{:.1} %", 100.0 * v);
    let ratio = |v: f64| format!("{v:.3}");
    let show = |[lo, mid, hi]: [f64; 3], f: &dyn Fn(f64) -> String| {
        format!("{} / {} / {}", f(lo), f(mid), f(hi))
    };
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {} | {} of {} | {} | {} | {} |\n",
            r.label,
            r.seed,
            r.start.name(),
            r.settled_coarse(),
            r.orders.len(),
            show(r.spread(|o| o.started_coarse), &pct),
            show(r.spread(|o| r.ratio(o)), &ratio),
            show(r.spread(|o| o.recall_at_1), &pct),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::search::RuleSpec;

    #[test]
    fn a_fresh_plan_learns_from_its_trials_and_a_restarted_one_skips_them() {
        let map = sweep::tests::toy_map();
        let n = 100;
        let (plain, coarse, costs) = sweep::tests::toy_learned(n);
        let plan = LearnedPlan {
            plain: (&plain, &costs),
            coarse: (&coarse, &costs),
        };
        // every query's answer is image 0, which is right for the even ones
        let truth: Vec<HashSet<u32>> = (0..n)
            .map(|q| HashSet::from([if q % 2 == 0 { 0 } else { 3 }]))
            .collect();
        let setting = Setting::new(RuleSpec::new("fixed", Some(0.2)).unwrap(), 0);
        let replayed = Replayed {
            map: &map,
            plan,
            setting: &setting,
            truth: &truth,
            ranking: Ranking::top(1),
        };
        let r = replay(replayed, Start::Fresh, 3, 2);
        assert_eq!(r.len(), 3);
        // the coarse pass costs more on these queries: each fresh plan
        // starts with it in its trials and on one request in EXPLORE_EVERY
        let explored = (2 * CoarseChoice::TRIAL + 1..=2 * n as u64)
            .filter(|k| k.is_multiple_of(CoarseChoice::EXPLORE_EVERY))
            .count();
        let started = (CoarseChoice::TRIAL as usize + explored) as f64 / (2 * n) as f64;
        for o in &r {
            assert_eq!(o.settled_coarse, Some(false), "{o:?}");
            assert!((o.started_coarse - started).abs() < 1e-12, "{o:?}");
            assert!((o.recall_at_1 - 0.5).abs() < 1e-12, "{o:?}");
            // one plain tile at 10 ms, its quantization and voting
            assert!(o.median_ms >= 10.0 && o.median_ms < 12.0, "{o:?}");
        }
        // restarted after 2n requests: no trials, only the explorations of
        // requests 2n + 1 to 4n
        let explored = (2 * n as u64 + 1..=4 * n as u64)
            .filter(|k| k.is_multiple_of(CoarseChoice::EXPLORE_EVERY))
            .count();
        let restarted = replay(replayed, Start::Restarted, 3, 2);
        assert_eq!(restarted.len(), 3);
        for o in &restarted {
            assert_eq!(o.settled_coarse, Some(false), "{o:?}");
            let started = explored as f64 / (2 * n) as f64;
            assert!((o.started_coarse - started).abs() < 1e-12, "{o:?}");
            assert!((o.recall_at_1 - 0.5).abs() < 1e-12, "{o:?}");
        }
    }

    #[test]
    fn the_section_lists_every_row_with_its_spread() {
        let order = |coarse: bool, ms: f64| OrderReplay {
            started_coarse: if coarse { 0.8 } else { 0.1 },
            settled_coarse: Some(coarse),
            median_ms: ms,
            recall_at_1: 0.9,
        };
        let rows = [PlanOrders {
            label: "place-z 2.25 w=20".into(),
            start: Start::Restarted,
            seed: 2,
            full_median_ms: 20.0,
            passes: 3,
            orders: vec![order(true, 6.0), order(false, 10.0), order(true, 7.0)],
        }];
        let md = markdown(&rows);
        assert!(
            md.contains("3 passes, every pass in a random order of its own (3 orders a seed)"),
            "{md}"
        );
        assert!(
            md.contains("| place-z 2.25 w=20 | 2 | restarted | 2 of 3 | 10.0 % / 80.0 % / 80.0 % | 0.300 / 0.350 / 0.500 | 90.0 % / 90.0 % / 90.0 % |"),
            "{md}"
        );
        assert!(markdown(&[]).is_empty());
    }
}
