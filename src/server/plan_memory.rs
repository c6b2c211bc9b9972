//! The learned extraction plan kept across restarts (`search.tiles = "…,auto"`
//! with `search.remember_plan`): what each plan has cost
//! ([`crate::features::Learned`]) is written beside the map as
//! `<map>.plan.json` while the service runs (when it has changed, at most
//! every few seconds) and when it stops, and read back when it starts. A
//! restart then goes on from it instead of trying both plans again on its
//! first requests, where a server whose trials came out wrong pays most
//! (docs/performance.md, "The learned plan over query orders"). The file
//! also keeps what tiles have cost ([`crate::search::budget::TileCosts`]),
//! so a time budget prices a restart's first requests as the last run's.
//!
//! What a plan costs depends on the map, the machine and the settings, so
//! the file names them ([`Context`]) and is used only when all three are
//! the ones running: another map file (a compaction while the service runs
//! is written into the file at its next save), another CPU model or
//! instruction set, another OpenCV CPU restriction, or other search,
//! verification or extraction settings start the trials again, and the log
//! says which. A file that cannot be read or parsed is logged and ignored;
//! one that cannot be written is logged once: a plan not kept costs the
//! next start its trials, never a request.

use super::config::Config;
use crate::features::Learned;
use crate::pipeline::Localizer;
use crate::search::budget::TileCosts;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, OnceLock};

/// The file's format; another is ignored.
pub const VERSION: u32 = 1;

/// The file beside `map` that keeps its learned plan.
pub fn path_for(map: &Path) -> PathBuf {
    let mut name = map.as_os_str().to_owned();
    name.push(".plan.json");
    PathBuf::from(name)
}

/// What a plan's costs were measured on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Context {
    /// The map file's fingerprint (hex).
    pub map: String,
    /// The vocabulary's hash (hex).
    pub vocabulary: String,
    /// The CPU model and its instruction-set level (SIFT's output and
    /// speed follow the level OpenCV dispatches to).
    pub cpu: String,
    /// Logical CPUs the process may use.
    pub cpus: usize,
    /// `OPENCV_CPU_DISABLE`, when set.
    pub opencv_cpu_disable: Option<String>,
    /// The settings a request's cost depends on: `[search]`, `[verify]`,
    /// OpenCV's threads, tiles ahead and the feature cap.
    pub settings: serde_json::Value,
}

impl Context {
    /// What differs from `other`, named for the log (`None`: nothing).
    pub fn differs_from(&self, other: &Context) -> Option<&'static str> {
        if self.map != other.map || self.vocabulary != other.vocabulary {
            Some("another map")
        } else if self.cpu != other.cpu
            || self.cpus != other.cpus
            || self.opencv_cpu_disable != other.opencv_cpu_disable
        {
            Some("another machine")
        } else if self.settings != other.settings {
            Some("other settings")
        } else {
            None
        }
    }
}

/// The file's content.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Saved {
    pub version: u32,
    pub context: Context,
    pub learned: Learned,
    /// What tiles have cost (absent from a file written before it was kept:
    /// learnt afresh).
    #[serde(default)]
    pub tile_costs: Option<TileCosts>,
}

/// What a save writes, but for the context's machine and settings: the
/// plan, what tiles cost and the map file they were learnt on.
type Kept = (Learned, TileCosts, String);

/// What [`PlanMemory::restore`] found.
#[derive(Debug, PartialEq)]
pub enum Restored {
    /// The plan goes on from the file's.
    Resumed(Learned),
    /// No file: the plan starts with its trials.
    Missing,
    /// A file for another context, or one that cannot be used: why.
    Ignored(String),
}

/// Keeps one map's learned plan in its file.
#[derive(Debug)]
pub struct PlanMemory {
    path: PathBuf,
    /// The context but for the map and vocabulary, which are read at each
    /// save (a compaction writes a new map file).
    here: Context,
    /// What the file holds now, as far as this process knows.
    saved: Mutex<Option<Kept>>,
    /// The requests of the plan resumed at start (`None`: none was).
    resumed: OnceLock<u64>,
    /// A failed write was logged as a warning.
    warned: AtomicBool,
}

impl PlanMemory {
    /// The memory of `config`'s map, when its plan is learned and to be
    /// kept.
    pub fn of(config: &Config) -> Option<Self> {
        let learned = config.tiles().is_ok_and(|p| p.learn_coarse);
        (learned && config.search.remember_plan)
            .then(|| Self::at(path_for(&config.files.map), config))
    }

    /// A memory in `path` for the settings of `config` on this machine.
    pub fn at(path: PathBuf, config: &Config) -> Self {
        let cpu = crate::eval::machine::Cpu::here();
        let here = Context {
            map: String::new(),
            vocabulary: String::new(),
            cpu: format!("{} ({})", cpu.model, cpu.instruction_set),
            cpus: cpu.cpus,
            opencv_cpu_disable: cpu.opencv_cpu_disable,
            settings: serde_json::json!({
                "search": config.search,
                "verify": config.verify,
                "opencv_threads": config.server.opencv_threads,
                "tiles_ahead": config.server.tiles_ahead,
                "max_features": config.limits.max_features,
            }),
        };
        Self {
            path,
            here,
            saved: Mutex::new(None),
            resumed: OnceLock::new(),
            warned: AtomicBool::new(false),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The requests of the plan resumed at start, when one was.
    pub fn resumed(&self) -> Option<u64> {
        self.resumed.get().copied()
    }

    /// The context of `localizer`'s map on this machine with these settings.
    pub fn context(&self, localizer: &Localizer) -> Context {
        Context {
            map: format!("{:016x}", localizer.map.snapshot().base().fingerprint()),
            vocabulary: localizer.vocab.hash_hex(),
            ..self.here.clone()
        }
    }

    /// Resume `localizer`'s learned plan, and what its tiles cost, from the
    /// file, when they were learned in the context running now.
    pub fn restore(&self, localizer: &Localizer) -> Restored {
        let Some(choice) = &localizer.coarse_choice else {
            return Restored::Ignored("the plan is not learned".into());
        };
        let text = match std::fs::read_to_string(&self.path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Restored::Missing,
            Err(e) => return Restored::Ignored(format!("cannot read it: {e}")),
        };
        let saved: Saved = match serde_json::from_str(&text) {
            Ok(saved) => saved,
            Err(e) => return Restored::Ignored(format!("not a plan file: {e}")),
        };
        if saved.version != VERSION {
            return Restored::Ignored(format!(
                "format {} (this version reads {VERSION})",
                saved.version
            ));
        }
        if let Some(why) = saved.context.differs_from(&self.context(localizer)) {
            return Restored::Ignored(format!("learned for {why}"));
        }
        if let Some(why) = saved.learned.invalid() {
            return Restored::Ignored(why);
        }
        let tile_cost = localizer.tile_cost();
        if let Some(costs) = saved.tile_costs
            && let Err(why) = tile_cost.resume(costs)
        {
            return Restored::Ignored(why);
        }
        if let Err(why) = choice.resume(saved.learned) {
            return Restored::Ignored(why);
        }
        *self.saved.lock().unwrap_or_else(|e| e.into_inner()) =
            Some((saved.learned, tile_cost.learnt(), saved.context.map.clone()));
        let _ = self.resumed.set(saved.learned.requests);
        Restored::Resumed(saved.learned)
    }

    /// Write `localizer`'s learned plan and what its tiles cost to the file
    /// when they, or the map file (a compaction), changed since the last
    /// write, and something was learnt (atomically: a reader sees the old
    /// file or the new). Returns whether it wrote.
    pub fn save(&self, localizer: &Localizer) -> bool {
        let Some(choice) = &localizer.coarse_choice else {
            return false;
        };
        let learned = choice.learned();
        let tile_cost = localizer.tile_cost();
        let context = self.context(localizer);
        let mut saved = self.saved.lock().unwrap_or_else(|e| e.into_inner());
        let now = (learned, tile_cost.learnt(), context.map.clone());
        let learnt = learned.requests > 0 || tile_cost.has_learnt();
        if saved.as_ref() == Some(&now) || !learnt {
            return false;
        }
        let file = Saved {
            version: VERSION,
            context,
            learned,
            tile_costs: Some(now.1.clone()),
        };
        let written = crate::store::write_atomic(&self.path, |w| {
            serde_json::to_writer_pretty(&mut *w, &file)?;
            w.write_all(b"\n")
        });
        match written {
            Ok(()) => {
                *saved = Some(now);
                true
            }
            Err(e) => {
                if !self.warned.swap(true, Ordering::Relaxed) {
                    tracing::warn!(
                        "cannot keep the learned plan (a restart will try both plans again): {e}"
                    );
                } else {
                    tracing::debug!("cannot keep the learned plan: {e}");
                }
                false
            }
        }
    }

    /// [`PlanMemory::restore`], logged.
    pub fn restore_logged(&self, localizer: &Localizer) {
        let path = self.path.display();
        let first_tiles_ms = || match localizer.tile_cost().tiles_to_beat_the_pass(false) {
            Some(t) => format!("{:.1}", t.as_secs_f64() * 1e3),
            None => "not learnt".into(),
        };
        match self.restore(localizer) {
            Restored::Resumed(l) => tracing::info!(
                file = %path,
                requests = l.requests,
                tiles_ms = l.tiles.typical_ms(),
                coarse_ms = l.coarse.typical_ms(),
                first_tiles_ms = %first_tiles_ms(),
                "learned plan resumed"
            ),
            Restored::Missing => {
                tracing::info!(file = %path, "no learned plan kept yet: trying both plans")
            }
            Restored::Ignored(why) => tracing::info!(
                file = %path,
                "learned plan not resumed ({why}): trying both plans"
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn context() -> Context {
        Context {
            map: "00000000000000aa".into(),
            vocabulary: "bb".into(),
            cpu: "Some CPU (AVX2)".into(),
            cpus: 2,
            opencv_cpu_disable: None,
            settings: serde_json::json!({"search": {"rule": "place-z"}}),
        }
    }

    #[test]
    fn a_context_names_what_differs() {
        let c = context();
        assert_eq!(c.differs_from(&c.clone()), None);
        let map = Context {
            map: "01".into(),
            ..context()
        };
        assert_eq!(c.differs_from(&map), Some("another map"));
        let cpu = Context {
            cpu: "Some CPU (AVX-512)".into(),
            ..context()
        };
        assert_eq!(c.differs_from(&cpu), Some("another machine"));
        let disabled = Context {
            opencv_cpu_disable: Some("AVX512_SKX".into()),
            ..context()
        };
        assert_eq!(c.differs_from(&disabled), Some("another machine"));
        let settings = Context {
            settings: serde_json::json!({"search": {"rule": "relative"}}),
            ..context()
        };
        assert_eq!(c.differs_from(&settings), Some("other settings"));
    }

    #[test]
    fn the_configuration_file_names_every_setting_a_plan_is_kept_for() {
        let memory = PlanMemory::at(PathBuf::from("m.plan.json"), &Config::default());
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/default.toml");
        let toml = std::fs::read_to_string(path).unwrap();
        // the comment lines right above the key
        let (above, _) = toml.split_once("\nremember_plan = ").unwrap();
        let comment: Vec<&str> = above
            .lines()
            .rev()
            .take_while(|l| l.starts_with('#'))
            .collect();
        let comment = comment.join(" ");
        let sections = ["search", "verify"];
        for key in memory.here.settings.as_object().unwrap().keys() {
            let named = match sections.contains(&key.as_str()) {
                true => comment.contains(&format!("[{key}]")),
                false => comment.contains(key.as_str()),
            };
            assert!(
                named,
                "config/default.toml's remember_plan must name {key}: {comment}"
            );
        }
    }

    #[test]
    fn the_file_sits_beside_the_map() {
        assert_eq!(
            path_for(Path::new("data/default/map.bowmap")),
            PathBuf::from("data/default/map.bowmap.plan.json")
        );
    }
}
