//! The machine an evaluation ran on, recorded with its results because
//! SIFT's output (and so every figure) depends on it: the CPU model and its
//! instruction-set level (from `/proc/cpuinfo`), OpenCV's version and the
//! SIMD level its dispatcher uses (read by the caller, since OpenCV stays at
//! the crate's edges), `OPENCV_CPU_DISABLE` when set, and the checksums of
//! the descriptors extracted.

use serde::Serialize;

/// OpenCV as the process loaded it.
#[derive(Debug, Clone, Default, Serialize)]
pub struct OpenCvInfo {
    pub version: String,
    /// `cv::getCPUFeaturesLine()`: baseline features bare, dispatched ones
    /// marked `*`, ones built but missing from this CPU marked `?`.
    pub cpu_features: String,
    /// The highest dispatched feature this CPU has (e.g. `AVX512_SKX`).
    pub dispatched: String,
}

impl OpenCvInfo {
    /// The highest feature of a `getCPUFeaturesLine()` line that is
    /// dispatched (`*`) and present on this CPU (no `?`); else the last
    /// baseline feature; else "none".
    pub fn dispatched_level(line: &str) -> String {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        tokens
            .iter()
            .rev()
            .find(|t| t.starts_with('*') && !t.ends_with('?'))
            .or_else(|| {
                tokens
                    .iter()
                    .rev()
                    .find(|t| !t.starts_with('*') && !t.ends_with('?'))
            })
            .map_or_else(
                || "none".to_owned(),
                |t| t.trim_start_matches('*').to_owned(),
            )
    }
}

/// Where the evaluation ran.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MachineInfo {
    pub cpu_model: String,
    /// Logical CPUs the process may use.
    pub cpus: usize,
    /// The widest vector instruction set the CPU reports: AVX-512, AVX2,
    /// AVX, SSE4.2 or baseline.
    pub instruction_set: String,
    pub opencv: OpenCvInfo,
    /// `OPENCV_CPU_DISABLE`, when set (it changes SIFT's output).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub opencv_cpu_disable: Option<String>,
    /// Checksums of the map's and the queries' descriptors (hex).
    pub map_descriptors: String,
    pub query_descriptors: String,
}

/// The CPU model and instruction-set level from the text of `/proc/cpuinfo`.
pub fn cpu_from(cpuinfo: &str) -> (String, String) {
    let field = |name: &str| {
        cpuinfo
            .lines()
            .find(|l| l.split(':').next().is_some_and(|k| k.trim() == name))
            .and_then(|l| l.split_once(':'))
            .map(|(_, v)| v.trim().to_owned())
    };
    let model = field("model name")
        .or_else(|| field("Model"))
        .unwrap_or_else(|| "unknown".to_owned());
    let flags = field("flags").unwrap_or_default();
    let has = |f: &str| flags.split_whitespace().any(|x| x == f);
    let level = if has("avx512f") {
        "AVX-512"
    } else if has("avx2") {
        "AVX2"
    } else if has("avx") {
        "AVX"
    } else if has("sse4_2") {
        "SSE4.2"
    } else if flags.is_empty() {
        "unknown"
    } else {
        "baseline"
    };
    (model, level.to_owned())
}

/// This machine's CPU as SIFT's speed and output depend on it.
#[derive(Debug, Clone, PartialEq)]
pub struct Cpu {
    pub model: String,
    /// As [`cpu_from`] names it.
    pub instruction_set: String,
    /// Logical CPUs the process may use.
    pub cpus: usize,
    /// `OPENCV_CPU_DISABLE`, when set.
    pub opencv_cpu_disable: Option<String>,
}

impl Cpu {
    /// The CPU this process runs on (`/proc/cpuinfo`, the environment).
    pub fn here() -> Self {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let (model, instruction_set) = cpu_from(&cpuinfo);
        Self {
            model,
            instruction_set,
            cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
            opencv_cpu_disable: std::env::var("OPENCV_CPU_DISABLE").ok(),
        }
    }
}

impl MachineInfo {
    /// This machine, with OpenCV's own description and the descriptors'
    /// checksums.
    pub fn here(opencv: OpenCvInfo, map_descriptors: u64, query_descriptors: u64) -> Self {
        let cpu = Cpu::here();
        Self {
            cpu_model: cpu.model,
            cpus: cpu.cpus,
            instruction_set: cpu.instruction_set,
            opencv,
            opencv_cpu_disable: cpu.opencv_cpu_disable,
            map_descriptors: format!("{map_descriptors:016x}"),
            query_descriptors: format!("{query_descriptors:016x}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_level_from_flags() {
        let text =
            "processor\t: 0\nmodel name\t: AMD EPYC 7B13\nflags\t\t: fpu sse4_2 avx avx2 fma\n";
        assert_eq!(
            cpu_from(text),
            ("AMD EPYC 7B13".to_owned(), "AVX2".to_owned())
        );
        let text = "model name : X\nflags : sse4_2 avx avx2 avx512f avx512bw\n";
        assert_eq!(cpu_from(text).1, "AVX-512");
        assert_eq!(cpu_from("").0, "unknown");
    }

    #[test]
    fn dispatched_level_skips_features_the_cpu_lacks() {
        let line = "SSE SSE2 SSE3 *SSE4_1 *SSE4_2 *FP16 *AVX *AVX2 *AVX512_SKX?";
        assert_eq!(OpenCvInfo::dispatched_level(line), "AVX2");
        assert_eq!(OpenCvInfo::dispatched_level("SSE SSE2"), "SSE2");
        assert_eq!(OpenCvInfo::dispatched_level(""), "none");
    }
}
