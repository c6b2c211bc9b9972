//! How much the learned coarse-pass plan (`--tiles …,auto`) depends on the
//! order its queries come in. The sweep replays one plan over the dataset's
//! order, as a server sent the queries in turn would learn it; here fresh
//! plans, each a server just started, see the queries as many times as the
//! sweep has runs, each time in a random order of their own (`--plan-orders
//! N`), and each order reports the share of its
//! searches started with the coarse pass, the plan it settled on, its median
//! request time against the whole-image full search's, and its recall@1.

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

/// A setting's replays over query orders on one vocabulary.
#[derive(Debug, Clone, Serialize)]
pub struct PlanOrders {
    pub label: String,
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

/// Replay `orders` fresh plans of `setting`, each over `passes` passes of
/// the queries, every pass in a random order of its own (the sweep's runs,
/// shuffled); pass p of order k draws the feature orders of the sweep's run
/// k·passes + p. Request times and recall@1 are over every search.
pub fn replay(
    map: &MapIndex,
    plan: LearnedPlan<'_>,
    setting: &Setting,
    orders: u32,
    passes: u32,
    truth: &[HashSet<u32>],
    ranking: Ranking,
) -> Vec<OrderReplay> {
    let n = plan.plain.0.len();
    (0..orders)
        .into_par_iter()
        .map(|k| {
            let choice = CoarseChoice::default();
            let mut ms = Vec::with_capacity(n * passes as usize);
            let mut started = 0;
            let mut recall = Vec::with_capacity(passes as usize);
            for p in 0..passes {
                let run = k * passes + p;
                let mut outcomes: Vec<Option<Outcome>> = vec![None; n];
                for q in permutation(n, ORDER_SALT ^ u64::from(run)) {
                    let q = q as usize;
                    let at = sweep::seed(run, q);
                    let o =
                        sweep::learned_search(map, plan, setting, Some(&choice), q, at, ranking);
                    ms.push(stage_sample(&o, plan.cost(&o, q)).total());
                    started += usize::from(o.coarse);
                    outcomes[q] = Some(o);
                }
                let outcomes: Vec<Outcome> = outcomes.into_iter().flatten().collect();
                recall.push(metrics::recall_at(&answers(&outcomes, truth), 1));
            }
            OrderReplay {
                started_coarse: started as f64 / ms.len().max(1) as f64,
                settled_coarse: choice.preferred(),
                median_ms: median(&ms),
                recall_at_1: metrics::mean(&recall),
            }
        })
        .collect()
}

/// The `results.md` section: one row per setting and vocabulary seed.
pub fn markdown(rows: &[PlanOrders]) -> String {
    let Some(first) = rows.first() else {
        return String::new();
    };
    let mut out = format!(
        "\n## The learned plan over query orders\n\n\
         Each order is a fresh plan (a server just started) that sees every query \
         once in each of {} passes, every pass in a random order of its own ({} \
         orders a seed). `settled coarse`: \
         orders whose plan preferred the coarse pass after the last query; `started \
         coarse` and `× full search` (its median request against the whole-image full \
         search's median): min / median / max over the orders.\n\n\
         | setting | seed | settled coarse | started coarse | × full search | recall@1 |\n\
         | --- | --- | --- | --- | --- | --- |\n",
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
            "| {} | {} | {} of {} | {} | {} | {} |\n",
            r.label,
            r.seed,
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
    fn every_order_is_a_fresh_plan_that_learns_from_its_trials() {
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
        let r = replay(&map, plan, &setting, 3, 2, &truth, Ranking::top(1));
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
            md.contains("| place-z 2.25 w=20 | 2 | 2 of 3 | 10.0 % / 80.0 % / 80.0 % | 0.300 / 0.350 / 0.500 | 90.0 % / 90.0 % / 90.0 % |"),
            "{md}"
        );
        assert!(markdown(&[]).is_empty());
    }
}
