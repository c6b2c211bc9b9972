//! Each rule on hand-built vote streams. The map has 4 images, image j holding
//! only word j, so a feature of word j adds exactly U = ln(4) to h(j) and
//! nothing elsewhere: every statistic along a stream is known by hand.

use super::*;
use crate::index::{ImageWords, MapBuilder, MapIndex};
use crate::search::vote::{Needs, VoteStats, Voter};

fn one_word_per_image() -> MapIndex {
    one_word_each(4)
}

/// A map of `images` images, image j holding only word j.
fn one_word_each(images: u32) -> MapIndex {
    let mut b = MapBuilder::new(images as usize);
    for j in 0..images {
        b.add(ImageWords::from_words(format!("{j}"), &[j]));
    }
    b.build("t", "0", None)
}

/// The feature count (1-based) at which `rule` stops on `stream`, checking
/// from feature `from` on; `None` if it never does.
fn stops_at(spec: RuleSpec, stream: &[u32], total: usize, from: usize) -> Option<usize> {
    stops_on(
        &one_word_per_image(),
        &RuleContext::default(),
        spec,
        stream,
        Some(total),
        from,
    )
}

/// The feature count at which `rule`, built in `context`, stops on `stream`
/// over `map`, checking from feature `from` on, the voter tracking what the
/// rule needs and knowing the query's `total` features if given.
fn stops_on(
    map: &MapIndex,
    context: &RuleContext,
    spec: RuleSpec,
    stream: &[u32],
    total: Option<usize>,
    from: usize,
) -> Option<usize> {
    let view = map.view();
    let mut rule = spec.build(context);
    let mut voter = Voter::with_needs(&view, rule.needs());
    if let Some(n) = total {
        voter.set_total(n);
    }
    for &w in stream {
        voter.vote(w, 0);
        if voter.tally().features >= from && rule.check(&voter).is_some() {
            return Some(voter.tally().features);
        }
    }
    None
}

/// The vote of one feature for its image.
const U: f64 = std::f64::consts::LN_2 * 2.0;

fn spec(name: &str, p: f64) -> RuleSpec {
    RuleSpec::new(name, Some(p)).unwrap()
}

#[test]
fn peak_mean_stops_exactly_when_gap_exceeds_threshold() {
    // max − mean along [0,1,0,0,0]: 0.75u, 0.5u, 1.25u, 2u, 2.75u
    let s = [0, 1, 0, 0, 0];
    let n = 10;
    assert_eq!(stops_at(spec("peak-mean", 1.5 * U), &s, n, 1), Some(4));
    assert_eq!(stops_at(spec("peak-mean", 0.6 * U), &s, n, 1), Some(1));
    assert_eq!(stops_at(spec("peak-mean", 2.5 * U), &s, n, 1), Some(5));
    assert_eq!(stops_at(spec("peak-mean", 3.0 * U), &s, n, 1), None);
}

#[test]
fn relative_stops_exactly_when_ratio_exceeds_threshold() {
    // (max − mean)/mean along [0,1,0,0,0]: 3, 1, 5/3, 2, 2.2
    let s = [0, 1, 0, 0, 0];
    assert_eq!(stops_at(spec("relative", 2.1), &s, 10, 1), Some(1));
    assert_eq!(stops_at(spec("relative", 2.1), &s, 10, 2), Some(5));
    assert_eq!(stops_at(spec("relative", 1.8), &s, 10, 2), Some(4));
    assert_eq!(stops_at(spec("relative", 2.5), &s, 10, 2), None);
}

#[test]
fn stable_peak_counts_features_since_the_last_change() {
    // leader: 0 from t=1 (keeps it at the t=2 tie: ties go to the lower id),
    // 1 from t=3, 0 again from t=4 (tie at 2u)
    let s = [0, 1, 1, 0, 0, 0, 0, 0];
    assert_eq!(stops_at(spec("stable-peak", 1.0), &s, 10, 1), Some(2));
    assert_eq!(stops_at(spec("stable-peak", 2.0), &s, 10, 1), Some(6));
    assert_eq!(stops_at(spec("stable-peak", 3.0), &s, 10, 1), Some(7));
    assert_eq!(stops_at(spec("stable-peak", 4.0), &s, 10, 1), Some(8));
    assert_eq!(stops_at(spec("stable-peak", 5.0), &s, 10, 1), None);
}

#[test]
fn hoeffding_stops_when_gap_meets_bound() {
    // all votes to image 0: scaled mean gap is 1, bound √(2 ln(2/δ)/t) ≤ 1
    // from t ≥ 2 ln(2/δ): δ = 0.1 → t ≥ 5.99 → stops at 6.
    let s = [0u32; 20];
    assert_eq!(stops_at(spec("hoeffding", 0.1), &s, 20, 1), Some(6));
    // δ = 0.01 → t ≥ 2 ln 200 = 10.6 → 11
    assert_eq!(stops_at(spec("hoeffding", 0.01), &s, 20, 1), Some(11));
    // alternating leaders never separate
    let alt: Vec<u32> = (0..20).map(|i| i % 2).collect();
    assert_eq!(stops_at(spec("hoeffding", 0.1), &alt, 20, 1), None);
}

#[test]
fn fixed_stops_at_the_fraction() {
    let s = [3u32; 10];
    assert_eq!(stops_at(spec("fixed", 0.3), &s, 10, 1), Some(3));
    assert_eq!(stops_at(spec("fixed", 0.25), &s, 10, 1), Some(3));
    assert_eq!(stops_at(spec("fixed", 1.0), &s, 10, 1), Some(10));
}

#[test]
fn lossless_waits_until_the_lead_exceeds_what_is_left() {
    // top 1; every feature gives u to one image; cap_j = u for all j.
    // Stream of N = 10 all to image 0: after t, h0 = t·u and the runner-up
    // has 0 but may gain (10 − t)·u: final once t > 10 − t, i.e. t = 6.
    let s = [0u32; 10];
    let lossless = || RuleSpec::new("lossless", None).unwrap();
    assert_eq!(stops_at(lossless(), &s, 10, 1), Some(6));
    // with a challenger: [0,0,1,0,0,0,0,0,0,0]: h0 − h1 must exceed (10 − t)·u:
    // t=6: 5u − u = 4u ≤ 4u; t=7: 6u − u = 5u > 3u
    let s = [0, 0, 1, 0, 0, 0, 0, 0, 0, 0];
    assert_eq!(stops_at(lossless(), &s, 10, 1), Some(7));
}

#[test]
fn lossless_orders_the_whole_top_n() {
    let map = one_word_per_image();
    let view = map.view();
    // top 2 of 4: image 0 then image 1 must be final and ordered
    let stream = [0, 1, 0, 1, 0, 0, 0, 0, 0, 0, 0, 1];
    let mut voter = Voter::with_needs(
        &view,
        Needs {
            top: 3,
            ..Needs::default()
        },
    );
    voter.set_total(stream.len());
    let mut rule = RuleSpec::new("lossless", None)
        .unwrap()
        .build(&RuleContext {
            top_n: 2,
            ..Default::default()
        });
    let mut stopped = None;
    for &w in &stream {
        voter.vote(w, 0);
        if rule.check(&voter).is_some() {
            stopped = Some(voter.tally().features);
            break;
        }
    }
    // after t: need h0 > h1 + (12 − t)u and h1 > 0 + (12 − t)u.
    // t=9: h0 = 7u, h1 = 2u: 7 > 2 + 3 yes; 2 > 3 no. t=10: 2 > 2 no. t=11: 2 > 1 yes.
    assert_eq!(stopped, Some(11));
}

#[test]
fn confident_needs_more_evidence_for_smaller_delta() {
    let s = [0u32; 400];
    let at = |d: f64| stops_at(spec("confident", d), &s, 400, 1).unwrap();
    assert!(
        at(0.5) <= at(0.05) && at(0.05) <= at(0.001),
        "{} {} {}",
        at(0.5),
        at(0.05),
        at(0.001)
    );
    // alternating leaders give no evidence
    let alt: Vec<u32> = (0..400).map(|i| i % 2).collect();
    assert_eq!(stops_at(spec("confident", 0.1), &alt, 400, 1), None);
}

#[test]
fn rules_that_need_n_wait_while_it_is_unknown() {
    // lossless cannot bound what is left without N; fixed uses the estimate
    let map = one_word_per_image();
    let view = map.view();
    let mut voter = Voter::new(&view);
    let mut lossless = RuleSpec::new("lossless", None)
        .unwrap()
        .build(&RuleContext::default());
    let mut fixed = spec("fixed", 0.5).build(&RuleContext::default());
    voter.set_expected_total(8.0);
    for _ in 0..3 {
        voter.vote(0, 0);
        assert!(lossless.check(&voter).is_none());
        assert!(fixed.check(&voter).is_none());
    }
    voter.vote(0, 0);
    assert!(fixed.check(&voter).is_some(), "4 of about 8 features");
    assert!(lossless.check(&voter).is_none());
    voter.set_total(5);
    assert!(lossless.check(&voter).is_some(), "4u > 1 feature left");
}

#[test]
fn none_never_stops() {
    let s = [0u32; 10];
    assert_eq!(
        stops_at(RuleSpec::new("none", None).unwrap(), &s, 10, 1),
        None
    );
}

#[test]
fn bad_specs_are_refused_with_reasons() {
    let err = RuleSpec::new("nope", Some(1.0)).unwrap_err();
    assert!(
        err.contains("unknown rule") && err.contains("peak-mean"),
        "{err}"
    );
    assert!(
        RuleSpec::new("peak-mean", None)
            .unwrap_err()
            .contains("threshold")
    );
    assert!(RuleSpec::new("peak-mean", Some(f64::NAN)).is_err());
    assert!(RuleSpec::new("peak-mean", Some(-1.0)).is_err());
    assert!(RuleSpec::new("hoeffding", Some(0.0)).is_err());
    assert!(RuleSpec::new("hoeffding", Some(1.0)).is_err());
    assert!(RuleSpec::new("fixed", Some(1.5)).is_err());
    assert!(RuleSpec::new("stable-peak", Some(2.5)).is_err());
    assert!(
        RuleSpec::new("none", Some(3.0))
            .unwrap_err()
            .contains("takes no parameter")
    );
}

#[test]
fn parameters_are_parsed_the_same_way_everywhere() {
    let p = |name: &str, given: &[(&str, f64)]| parse_rule(name, given);
    assert_eq!(p("relative", &[("threshold", 2.5)]).unwrap().parameter, 2.5);
    assert_eq!(p("hoeffding", &[("delta", 0.1)]).unwrap().parameter, 0.1);
    // the generic name is accepted for any rule's parameter
    assert_eq!(p("fixed", &[("threshold", 0.5)]).unwrap().parameter, 0.5);
    assert_eq!(p("verified", &[("inliers", 12.0)]).unwrap().parameter, 12.0);
    let err = |name: &str, given: &[(&str, f64)]| p(name, given).unwrap_err();
    assert_eq!(
        err("none", &[("threshold", 2.5)]).parameter.as_deref(),
        Some("threshold")
    );
    assert!(
        err("peak-mean", &[("delta", 0.1)])
            .message
            .contains("takes `threshold`, not `delta`")
    );
    assert!(err("relative", &[]).message.contains("needs its threshold"));
    assert!(err("verified", &[]).message.contains("needs its inliers"));
    assert!(
        err("verified", &[("epsilon", 0.1)])
            .message
            .contains("takes `inliers`, not `epsilon`")
    );
    assert!(
        err("relative", &[("threshold", 1.0), ("delta", 0.1)])
            .message
            .contains("give one")
    );
    assert_eq!(err("nope", &[]).parameter, None);
    assert!(
        err("verified", &[("inliers", 3.0)])
            .message
            .contains("4..=1000")
    );
}

#[test]
fn every_rule_has_all_its_parts() {
    for r in RULES {
        assert!(!r.about.is_empty(), "{}", r.name);
        match (&r.parameter, r.grid) {
            (None, Grid::Single) => {
                RuleSpec::new(r.name, None).unwrap();
            }
            (None, _) => panic!("{}: a grid for a rule without a parameter", r.name),
            (Some(_), Grid::Single) => panic!("{}: a parameter without a grid", r.name),
            (Some(p), grid) => {
                assert!(!p.meaning.is_empty(), "{}", r.name);
                assert!(parameter_names().contains(&p.name));
                RuleSpec::new(r.name, Some(p.example)).unwrap();
                match grid {
                    Grid::Values(vs) => {
                        assert!(!vs.is_empty());
                        for &v in vs {
                            RuleSpec::new(r.name, Some(v)).unwrap();
                        }
                    }
                    Grid::Calibrated { lo, hi, .. } => {
                        assert!(lo < hi);
                        RuleSpec::new(r.name, Some(lo)).unwrap();
                        RuleSpec::new(r.name, Some(hi)).unwrap();
                    }
                    Grid::Single => unreachable!(),
                }
            }
        }
        assert!(rules_markdown().contains(&format!("| `{}` |", r.name)));
    }
}

#[test]
fn every_registered_rule_has_a_unique_name() {
    let mut names = rule_names();
    names.sort();
    names.dedup();
    assert_eq!(names.len(), RULES.len());
}

/// Feature 0, word 0.
const VOTED_0: Voted = Voted {
    feature: 0,
    word: 0,
    signature: 0,
};

/// A geometric check that finds `inliers` for image 0 and none elsewhere,
/// counting its calls; image 0's inliers show the scene at `scale`.
struct FakeCheck {
    inliers: usize,
    calls: usize,
    scale: f32,
}

impl FakeCheck {
    fn inliers(&mut self, image: u32, voted: &[Voted]) -> usize {
        self.calls += 1;
        assert!(!voted.is_empty());
        if image == 0 { self.inliers } else { 0 }
    }
}

impl LeaderCheck for FakeCheck {
    /// Image 0 first when it is a candidate, else the first candidate.
    fn answer(
        &mut self,
        candidates: &[(u32, f32)],
        voted: &[Voted],
        _min_inliers: usize,
    ) -> Option<CheckedAnswer> {
        let first = candidates
            .iter()
            .find(|c| c.0 == 0)
            .or(candidates.first())?;
        let inliers = self.inliers(first.0, voted);
        Some(CheckedAnswer {
            id: first.0,
            inliers,
            scale: (inliers > 0).then_some(self.scale),
        })
    }
}

fn verified_stop(m: f64, stream: &[u32], check: &mut FakeCheck) -> Option<usize> {
    stops_with_check(&spec("verified", m), stream, Some(check))
}

#[test]
fn verified_checks_the_leader_whenever_offered_and_stops_at_m_inliers() {
    let s = [0u32; 200];
    let mut c = FakeCheck {
        inliers: 12,
        calls: 0,
        scale: 1.0,
    };
    // the first check offered verifies the leader
    assert_eq!(verified_stop(12.0, &s, &mut c), Some(1));
    assert_eq!(c.calls, 1);
    // too few inliers: checked at every offer, never stops
    let mut c = FakeCheck {
        inliers: 12,
        calls: 0,
        scale: 1.0,
    };
    assert_eq!(verified_stop(13.0, &s, &mut c), None);
    assert_eq!(c.calls, 200);
    // a leader without inliers never stops the search
    let s = [1u32; 200];
    let mut c = FakeCheck {
        inliers: 50,
        calls: 0,
        scale: 1.0,
    };
    assert_eq!(verified_stop(8.0, &s, &mut c), None);
    // the same leader on the same votes is not checked twice
    let map = one_word_per_image();
    let view = map.view();
    let mut voter = Voter::new(&view);
    let mut rule = spec("verified", 13.0).build(&RuleContext::default());
    let mut c = FakeCheck {
        inliers: 12,
        calls: 0,
        scale: 1.0,
    };
    voter.vote(0, 0);
    for _ in 0..3 {
        assert!(
            rule.check_with(&voter, Progress::new(&[VOTED_0], Some(&mut c), true))
                .is_none()
        );
    }
    assert_eq!(c.calls, 1);
    // without a check the rule never stops
    let map = one_word_per_image();
    let view = map.view();
    let mut voter = Voter::new(&view);
    let mut rule = spec("verified", 8.0).build(&RuleContext::default());
    for _ in 0..100 {
        voter.vote(0, 0);
        assert!(
            rule.check_with(&voter, Progress::new(&[VOTED_0], None, true))
                .is_none()
        );
    }
    // inside a batch, checks follow a geometric schedule: at 1, 2, 3, 5, 8,
    // 12, … features (each at least 1.5 times the last)
    let map = one_word_per_image();
    let view = map.view();
    let mut voter = Voter::new(&view);
    let mut rule = spec("verified", 13.0).build(&RuleContext::default());
    let mut c = FakeCheck {
        inliers: 12,
        calls: 0,
        scale: 1.0,
    };
    let mut voted = Vec::new();
    let mut checked_at = Vec::new();
    for i in 0..100u32 {
        voter.vote(0, 0);
        voted.push(Voted {
            feature: i,
            word: 0,
            signature: 0,
        });
        let before = c.calls;
        assert!(
            rule.check_with(&voter, Progress::new(&voted, Some(&mut c), false))
                .is_none()
        );
        if c.calls > before {
            checked_at.push(i + 1);
        }
    }
    assert_eq!(checked_at, [1, 2, 3, 5, 8, 12, 18, 27, 41, 62, 93]);
    assert!(RuleSpec::new("verified", Some(3.0)).is_err());
    assert!(RuleSpec::new("verified", Some(8.5)).is_err());
}

/// Where `rule` stops on `stream` (every check offered at a batch's end),
/// with `check` as the geometric check if given.
#[test]
fn verified_stops_on_the_checked_answer_at_the_query_scale_not_only_the_leader() {
    // image 0 verifies, but shows the scene 1.5 times larger than the
    // query: a near miss, never a stop
    let s = [0u32; 200];
    let mut c = FakeCheck {
        inliers: 50,
        calls: 0,
        scale: 1.5,
    };
    assert_eq!(verified_stop(8.0, &s, &mut c), None);
    assert_eq!(c.calls, 200);
    // image 1 leads the votes and image 0, second, verifies: with the top
    // 4 handed to the check the answer is image 0 once it has a vote, and
    // the search stops there; with the leader alone it never does
    let s = [1u32, 1, 0, 1, 0, 1];
    let top_4 = RuleContext {
        top_n: 4,
        ..RuleContext::default()
    };
    let mut c = FakeCheck {
        inliers: 8,
        calls: 0,
        scale: 1.1,
    };
    let stop = stops_with_check_in(&spec("verified", 8.0), &s, Some(&mut c), &top_4);
    assert_eq!(stop, Some(3));
    let mut c = FakeCheck {
        inliers: 8,
        calls: 0,
        scale: 1.1,
    };
    assert_eq!(verified_stop(8.0, &s, &mut c), None);
    assert_eq!(c.calls, s.len());
}

/// A [`FakeCheck`] with the bounds a real checker takes from its
/// verification settings: the query's scale, and the pairs the model's fit
/// takes.
struct Bounds {
    check: FakeCheck,
    max_log_scale: f32,
    fit_needs: usize,
}

impl LeaderCheck for Bounds {
    fn answer(
        &mut self,
        candidates: &[(u32, f32)],
        voted: &[Voted],
        min_inliers: usize,
    ) -> Option<CheckedAnswer> {
        self.check.answer(candidates, voted, min_inliers)
    }

    fn max_log_scale(&self) -> f32 {
        self.max_log_scale
    }

    fn fit_needs(&self) -> usize {
        self.fit_needs
    }
}

#[test]
fn the_checker_says_how_far_from_the_query_scale_a_geometric_stop_may_be() {
    // ln 1.15 ≈ 0.14: within the default bound (0.2), not within 0.1
    let s = [0u32; 50];
    let check = |max_log_scale| Bounds {
        check: FakeCheck {
            inliers: 20,
            calls: 0,
            scale: 1.15,
        },
        max_log_scale,
        fit_needs: 0,
    };
    for rule in [
        spec("verified", 8.0),
        spec("stable-peak", 1000.0).or_verified(Some(8.0)).unwrap(),
    ] {
        let mut c = check(MAX_LOG_SCALE);
        assert_eq!(stops_with_check(&rule, &s, Some(&mut c)), Some(1), "{rule}");
        let mut c = check(0.1);
        assert_eq!(stops_with_check(&rule, &s, Some(&mut c)), None, "{rule}");
        let mut c = check(0.5);
        assert_eq!(stops_with_check(&rule, &s, Some(&mut c)), Some(1), "{rule}");
    }
}

#[test]
fn a_geometric_stop_never_counts_the_pairs_a_fit_takes_as_evidence() {
    // a homography fits any 4 pairs: 4 inliers verify nothing, whatever m
    let s = [0u32; 50];
    let check = |inliers| Bounds {
        check: FakeCheck {
            inliers,
            calls: 0,
            scale: 1.0,
        },
        max_log_scale: MAX_LOG_SCALE,
        fit_needs: 4,
    };
    for rule in [
        spec("verified", 4.0),
        spec("stable-peak", 1000.0).or_verified(Some(4.0)).unwrap(),
    ] {
        let mut c = check(4);
        assert_eq!(stops_with_check(&rule, &s, Some(&mut c)), None, "{rule}");
        let mut c = check(5);
        assert_eq!(stops_with_check(&rule, &s, Some(&mut c)), Some(1), "{rule}");
    }
    // the trace shows the inliers the check needed, not m
    let map = one_word_per_image();
    let view = map.view();
    let mut voter = Voter::new(&view);
    let mut rule = spec("verified", 4.0).build(&RuleContext::default());
    voter.vote(0, 0);
    let mut c = check(4);
    assert!(
        rule.check_with(&voter, Progress::new(&[VOTED_0], Some(&mut c), true))
            .is_none()
    );
    assert_eq!(rule.statistic(&voter), Some((4.0, 5.0)));
}

fn stops_with_check(
    rule: &RuleSpec,
    stream: &[u32],
    check: Option<&mut dyn LeaderCheck>,
) -> Option<usize> {
    stops_with_check_in(rule, stream, check, &RuleContext::default())
}

/// [`stops_with_check`] for a rule built in `context`.
fn stops_with_check_in(
    rule: &RuleSpec,
    stream: &[u32],
    mut check: Option<&mut dyn LeaderCheck>,
    context: &RuleContext,
) -> Option<usize> {
    let map = one_word_per_image();
    let view = map.view();
    let mut rule_now = rule.build(context);
    let mut voter = Voter::with_needs(&view, rule_now.needs());
    let mut voted = Vec::new();
    for (i, &w) in stream.iter().enumerate() {
        voter.vote(w, 0);
        voted.push(Voted {
            feature: i as u32,
            word: w,
            signature: 0,
        });
        let offered = check.as_mut().map(|c| &mut **c as &mut dyn LeaderCheck);
        if rule_now
            .check_with(&voter, Progress::new(&voted, offered, true))
            .is_some()
        {
            return Some(voter.tally().features);
        }
    }
    None
}

#[test]
fn a_vote_rule_or_verified_stops_at_whichever_comes_first() {
    let s = [0u32; 200];
    let votes = spec("stable-peak", 50.0);
    let alone = stops_with_check(&votes, &s, None);
    assert!(alone.is_some_and(|t| t > 1), "{alone:?}");
    let either = votes.clone().or_verified(Some(12.0)).unwrap();
    assert!(either.geometric() && !either.shardable());
    assert!(votes.shardable() && !votes.geometric());
    assert_eq!(
        either.to_string(),
        "stable-peak (threshold 50) or verified at scale (inliers 12)"
    );
    // the answer verifies at the query's scale at the first check: the
    // check stops the search
    let mut c = FakeCheck {
        inliers: 12,
        calls: 0,
        scale: 1.0,
    };
    assert_eq!(stops_with_check(&either, &s, Some(&mut c)), Some(1));
    // it never verifies: the vote rule stops it where it would alone
    let mut c = FakeCheck {
        inliers: 11,
        calls: 0,
        scale: 1.0,
    };
    assert_eq!(stops_with_check(&either, &s, Some(&mut c)), alone);
    assert!(c.calls > 0);
    // enough inliers, but the scene 1.5 times larger in the map image than
    // in the query (a map image taken ahead of it): the vote rule alone;
    // at 1.2 times, within e^0.2, the check stops it
    for (scale, stop) in [(1.5, alone), (1.0 / 1.5, alone), (1.2, Some(1))] {
        let mut c = FakeCheck {
            inliers: 40,
            calls: 0,
            scale,
        };
        assert_eq!(stops_with_check(&either, &s, Some(&mut c)), stop, "{scale}");
    }
    // without a check, the vote rule alone
    assert_eq!(stops_with_check(&either, &s, None), alone);
    // it travels with the rule and is absent when not set
    let json = serde_json::to_string(&either).unwrap();
    assert_eq!(serde_json::from_str::<RuleSpec>(&json).unwrap(), either);
    assert!(
        !serde_json::to_string(&votes)
            .unwrap()
            .contains("or_verified")
    );
    // refused: a rule that cannot stop early, one that verifies already, and
    // inliers out of the verified rule's range
    assert!(
        RuleSpec::new("none", None)
            .unwrap()
            .or_verified(Some(12.0))
            .is_err()
    );
    assert!(spec("verified", 12.0).or_verified(Some(12.0)).is_err());
    // without inliers, any rule as it is
    let none = RuleSpec::new("none", None).unwrap();
    assert_eq!(none.clone().or_verified(None).unwrap(), none);
    // 0: the rule without the check, whatever it had
    assert_eq!(none.clone().or_verified(Some(0.0)).unwrap(), none);
    assert_eq!(either.clone().or_verified(Some(0.0)).unwrap(), votes);
    assert!(votes.clone().or_verified(Some(3.0)).is_err());
    assert!(votes.or_verified(Some(12.5)).is_err());
}

/// [`stops_on`] a map of `images` images, image j holding only word j, with
/// places of `place_window` images on each side.
fn stops_at_in_place(
    spec: RuleSpec,
    images: u32,
    place_window: u32,
    stream: &[u32],
) -> Option<usize> {
    let context = RuleContext {
        place_window,
        ..Default::default()
    };
    stops_on(&one_word_each(images), &context, spec, stream, None, 1)
}

#[test]
fn place_lead_compares_the_leader_with_the_best_other_place() {
    // 8 images, a vote u = ln 8 each. Along [0,1,1,0,0,5,0] the leader and
    // the best image outside its place are, with a place of ±1 image:
    // (0: u, –), (0: u, –), (1: 2u, –), (0: 2u, –), (0: 3u, –), (0: 3u, 5: u),
    // (0: 4u, 5: u): leads u, u, 2u, 2u, 3u, 2u, 3u.
    let u = 8f64.ln();
    let s = [0, 1, 1, 0, 0, 5, 0];
    let lead = |t| spec("place-lead", t);
    assert_eq!(stops_at_in_place(lead(1.5 * u), 8, 1, &s), Some(3));
    assert_eq!(stops_at_in_place(lead(2.5 * u), 8, 1, &s), Some(5));
    assert_eq!(stops_at_in_place(lead(3.5 * u), 8, 1, &s), None);
    // each image its own place: image 1 is a rival of image 0, leads
    // u, 0, u, 0, u, u, 2u
    assert_eq!(stops_at_in_place(lead(1.5 * u), 8, 0, &s), Some(7));
    assert_eq!(stops_at_in_place(lead(0.5 * u), 8, 0, &s), Some(1));
}

#[test]
fn place_lead_reads_enough_leaders_to_find_another_place() {
    // 12 images, a place of ±2: the five images of image 2's place lead
    // (4u, 3u, 3u, 2u, 2u) and the best image elsewhere, 9 (u), is only the
    // sixth best: the rule must track enough leaders to see it.
    let map = one_word_each(12);
    let view = map.view();
    let rule = spec("place-lead", 1.0).build(&RuleContext {
        place_window: 2,
        ..Default::default()
    });
    let mut voter = Voter::with_needs(&view, rule.needs());
    for w in [9, 2, 2, 2, 2, 1, 1, 1, 3, 3, 3, 0, 0, 4, 4] {
        voter.vote(w, 0);
    }
    let u = 12f64.ln();
    let (lead, threshold) = rule.statistic(&voter).unwrap();
    assert!(
        (lead - 3.0 * u).abs() < 1e-4,
        "lead {lead}, expected {}",
        3.0 * u
    );
    assert_eq!(threshold, 1.0);
}

#[test]
fn place_z_is_the_lead_over_the_best_other_place_in_units_of_its_spread() {
    // Every vote is u, so an image with c votes has h = c·u and Σv² = c·u²,
    // and z = (c_leader − c_other) / √(c_leader + c_other) whatever u is.
    // Along [0,1,1,0,0,5,0] with a place of ±1 image (leader: other):
    // (0: –) 1, (0: –) 1, (1: –) √2, (0: –) √2, (0: –) √3, (0: 5) 2/2 = 1,
    // (0: 5) 3/√5.
    let s = [0, 1, 1, 0, 0, 5, 0];
    for images in [8, 16, 64] {
        let z = |t| spec("place-z", t);
        assert_eq!(stops_at_in_place(z(1.2), images, 1, &s), Some(3));
        assert_eq!(stops_at_in_place(z(1.5), images, 1, &s), Some(5));
        assert_eq!(stops_at_in_place(z(1.8), images, 1, &s), None);
        // each image its own place, so 1 rivals 0: z = 1, 0, 1/√3, 0,
        // 1/√5, 1/√5, 2/√6; checked from the second feature on
        let own = RuleContext {
            place_window: 0,
            ..Default::default()
        };
        let map = one_word_each(images);
        assert_eq!(stops_on(&map, &own, z(0.5), &s, None, 2), Some(3));
        assert_eq!(stops_on(&map, &own, z(0.7), &s, None, 2), Some(7));
        assert_eq!(stops_on(&map, &own, z(0.9), &s, None, 2), None);
    }
}

/// `rule`'s statistic after `stream` on a map of `images` images, a place
/// of ±1 image.
fn statistic_after(name: &str, images: u32, stream: &[u32]) -> f64 {
    let map = one_word_each(images);
    let view = map.view();
    let rule = spec(name, 1.0).build(&RuleContext {
        place_window: 1,
        ..Default::default()
    });
    let mut voter = Voter::with_needs(&view, rule.needs());
    for &w in stream {
        voter.vote(w, 0);
    }
    rule.statistic(&voter).unwrap().0
}

#[test]
fn place_z_asks_more_lead_per_feature_of_a_long_query() {
    // The same lead of 2 votes, over the best other place, after 2 features
    // and after 10: `place-lead` sees the same evidence in both; `place-z`
    // sees 2/√2 against 2/√10.
    let short = [0, 0];
    let long = [0, 4, 0, 4, 0, 4, 0, 4, 0, 0];
    let u = 8f64.ln();
    let lead = |s: &[u32]| statistic_after("place-lead", 8, s);
    assert!((lead(&short) - 2.0 * u).abs() < 1e-4);
    assert!((lead(&long) - 2.0 * u).abs() < 1e-4);
    let z = |s: &[u32]| statistic_after("place-z", 8, s);
    assert!((z(&short) - 2f64.sqrt()).abs() < 1e-4, "{}", z(&short));
    assert!((z(&long) - 2.0 / 10f64.sqrt()).abs() < 1e-4, "{}", z(&long));
}

#[test]
fn or_verified_checks_only_at_a_tiles_end_with_tiles_left() {
    let rule = spec("stable-peak", 1000.0).or_verified(Some(12.0)).unwrap();
    let map = one_word_per_image();
    let view = map.view();
    let mut rule_now = rule.build(&RuleContext::default());
    let mut voter = Voter::with_needs(&view, rule_now.needs());
    let mut c = FakeCheck {
        inliers: 40,
        calls: 0,
        scale: 1.0,
    };
    voter.vote(0, 0);
    let voted = [Voted {
        feature: 0,
        word: 0,
        signature: 0,
    }];
    // inside a tile: no check
    assert!(
        rule_now
            .check_with(&voter, Progress::new(&voted, Some(&mut c), false))
            .is_none()
    );
    assert_eq!(c.calls, 0);
    // the last tile's end (N known): the search ends anyway, no check
    voter.set_total(1);
    assert!(
        rule_now
            .check_with(&voter, Progress::new(&voted, Some(&mut c), true))
            .is_none()
    );
    assert_eq!(c.calls, 0);
    // a tile's end with tiles left: checked, and it stops
    let mut rule_now = rule.build(&RuleContext::default());
    let mut voter = Voter::with_needs(&view, rule_now.needs());
    voter.vote(0, 0);
    voter.set_expected_total(4.0);
    let why = rule_now.check_with(&voter, Progress::new(&voted, Some(&mut c), true));
    assert_eq!(c.calls, 1);
    assert!(why.is_some_and(|w| w.contains("answer 0 verified at the query's scale")));
}

#[test]
fn on_a_coarse_pass_only_the_geometric_check_stops() {
    fn coarse<'a>(
        voted: &'a [Voted],
        check: Option<&'a mut dyn LeaderCheck>,
        batch_end: bool,
    ) -> Progress<'a> {
        Progress {
            coarse: true,
            ..Progress::new(voted, check, batch_end)
        }
    }
    let map = one_word_per_image();
    let view = map.view();
    // a vote rule that stops after one feature does not stop on it
    let mut votes_only = spec("fixed", 0.01).build(&RuleContext::default());
    let mut voter = Voter::with_needs(&view, votes_only.needs());
    voter.vote(0, 0);
    voter.set_expected_total(4.0);
    assert!(votes_only.check(&voter).is_some());
    assert!(
        votes_only
            .check_with(&voter, coarse(&[VOTED_0], None, true))
            .is_none()
    );
    // beside a verified stop, the vote rule still does not; the check does
    let rule = spec("fixed", 0.01).or_verified(Some(12.0)).unwrap();
    for (inliers, stops) in [(4, false), (40, true)] {
        let mut rule_now = rule.build(&RuleContext::default());
        let mut c = FakeCheck {
            inliers,
            calls: 0,
            scale: 1.0,
        };
        let why = rule_now.check_with(&voter, coarse(&[VOTED_0], Some(&mut c), true));
        assert_eq!(c.calls, 1);
        assert_eq!(why.is_some(), stops, "{inliers} inliers: {why:?}");
    }
    // `verified` checks a coarse pass as any tile
    let mut verified = spec("verified", 12.0).build(&RuleContext::default());
    let mut c = FakeCheck {
        inliers: 40,
        calls: 0,
        scale: 1.0,
    };
    assert!(
        verified
            .check_with(&voter, coarse(&[VOTED_0], Some(&mut c), true))
            .is_some()
    );
}

/// A check that records what each answer was asked for: how many
/// candidates and with what floor. It verifies nothing, and says its fit
/// takes 4 pairs.
#[derive(Default)]
struct RecordingCheck {
    candidates: Vec<usize>,
    floors: Vec<usize>,
}

impl LeaderCheck for RecordingCheck {
    fn answer(
        &mut self,
        candidates: &[(u32, f32)],
        _voted: &[Voted],
        min_inliers: usize,
    ) -> Option<CheckedAnswer> {
        self.candidates.push(candidates.len());
        self.floors.push(min_inliers);
        None
    }

    fn fit_needs(&self) -> usize {
        4
    }
}

#[test]
fn a_geometric_stop_asks_for_an_answer_verified_with_its_own_m() {
    // the answer it checks is verified with at least the inliers it needs
    // to stop (m, or more than the fit takes), whatever the verification's
    // own floor
    let map = one_word_per_image();
    let view = map.view();
    for (rule, expected) in [
        (spec("verified", 13.0), 13),
        (spec("verified", 4.0), 5),
        (
            spec("stable-peak", 1000.0).or_verified(Some(12.0)).unwrap(),
            12,
        ),
    ] {
        let mut rule_now = rule.build(&RuleContext::default());
        let mut voter = Voter::with_needs(&view, rule_now.needs());
        voter.vote(0, 0);
        voter.set_expected_total(4.0);
        let mut c = RecordingCheck::default();
        assert!(
            rule_now
                .check_with(&voter, Progress::new(&[VOTED_0], Some(&mut c), true))
                .is_none()
        );
        assert_eq!(c.floors, [expected], "{rule}");
    }
}

#[test]
fn or_verified_hands_the_check_the_searchs_top_n() {
    let map = one_word_each(8);
    let view = map.view();
    let rule = spec("stable-peak", 1000.0).or_verified(Some(12.0)).unwrap();
    for (top_n, expected) in [(1, 1), (3, 3), (20, 8)] {
        let mut rule_now = rule.build(&RuleContext {
            top_n,
            ..RuleContext::default()
        });
        let mut voter = Voter::with_needs(&view, rule_now.needs());
        for w in 0..8 {
            voter.vote(w, 0);
        }
        voter.set_expected_total(16.0);
        let mut c = RecordingCheck::default();
        assert!(
            rule_now
                .check_with(&voter, Progress::new(&[VOTED_0], Some(&mut c), true))
                .is_none()
        );
        assert_eq!(c.candidates, [expected], "top_n {top_n}");
    }
}
