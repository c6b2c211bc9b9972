//! A request's time budget: whether streaming extraction may extract one
//! more tile. A caller that must have an answer within a time (a robot's
//! control loop) gives the budget; after each tile the next one is taken
//! only if it is expected to end within it, the tiles so far telling what
//! a tile costs (its extraction, quantization and votes). The first tile is
//! always taken, so every answer has votes behind it. Plain arithmetic on
//! durations: the pipeline measures, this decides.

use std::time::Duration;

/// The longest budget accepted: ten minutes, far past any deadline.
pub const MAX_BUDGET: Duration = Duration::from_secs(600);

/// `ms` if it is an accepted budget in milliseconds (a finite number > 0,
/// at most [`MAX_BUDGET`]), else why not: the one check behind the
/// configuration, the API and `--budget-ms`.
pub fn check_ms(ms: f64) -> Result<Duration, String> {
    if ms.is_finite() && ms > 0.0 && ms <= MAX_BUDGET.as_millis() as f64 {
        Ok(Duration::from_secs_f64(ms / 1000.0))
    } else {
        Err(format!(
            "must be a number of milliseconds in (0, {}], got {ms}",
            MAX_BUDGET.as_millis()
        ))
    }
}

/// `Ok` when one more tile fits in `budget`, else why it does not (the
/// stop's detail). `spent`: the time since the request's work began
/// (decoding included); `tiles_cost`: the part of it the `tiles_done` tiles
/// took, whose mean is what the next tile is expected to take.
pub fn next_tile_fits(
    budget: Duration,
    spent: Duration,
    tiles_cost: Duration,
    tiles_done: usize,
) -> Result<(), String> {
    if tiles_done == 0 {
        return Ok(());
    }
    let next = tiles_cost / tiles_done as u32;
    if spent + next <= budget {
        return Ok(());
    }
    let ms = |d: Duration| d.as_secs_f64() * 1000.0;
    Err(format!(
        "time budget {:.1} ms: {:.1} ms spent, the next tile would take about {:.1} ms",
        ms(budget),
        ms(spent),
        ms(next)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn the_first_tile_is_always_taken() {
        assert!(next_tile_fits(MS, 50 * MS, Duration::ZERO, 0).is_ok());
    }

    #[test]
    fn a_tile_is_taken_while_the_mean_tile_fits() {
        // two tiles took 20 ms after 5 ms of decoding: the next takes ~10 ms
        assert!(next_tile_fits(35 * MS, 25 * MS, 20 * MS, 2).is_ok());
        let why = next_tile_fits(34 * MS, 25 * MS, 20 * MS, 2).unwrap_err();
        assert!(why.contains("34.0 ms"), "{why}");
        assert!(why.contains("about 10.0 ms"), "{why}");
        // already past the budget
        assert!(next_tile_fits(20 * MS, 25 * MS, 20 * MS, 2).is_err());
    }

    #[test]
    fn budgets_are_checked() {
        assert_eq!(check_ms(30.0), Ok(30 * MS));
        assert_eq!(check_ms(0.5), Ok(MS / 2));
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 600_001.0] {
            assert!(check_ms(bad).is_err(), "{bad}");
        }
        assert!(check_ms(600_000.0).is_ok());
    }
}
