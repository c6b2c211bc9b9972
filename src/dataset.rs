//! Image lists and the shared dataset layout: `map.txt` and `queries.txt`
//! (one image path a line, relative to the dataset folder; line order = id)
//! and `ground_truth.csv` (`query,match` rows of correct pairs).

use anyhow::{Context, bail};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// File extensions taken as images when a folder is given instead of a list.
const IMAGE_EXTENSIONS: &[&str] = &[
    "jpg", "jpeg", "png", "bmp", "tif", "tiff", "webp", "pgm", "ppm", "pbm",
];

/// An image to read: its display name (as listed) and where it is.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageRef {
    pub name: String,
    pub path: PathBuf,
}

/// Images named by a list file (paths relative to the list's folder, blank
/// lines and `#` comments skipped) or every image file in a folder, by name.
pub fn image_list(list_or_dir: &Path) -> anyhow::Result<Vec<ImageRef>> {
    let meta = std::fs::metadata(list_or_dir)
        .with_context(|| format!("{}: cannot read", list_or_dir.display()))?;
    let images: Vec<ImageRef> = if meta.is_dir() {
        let mut names: Vec<String> = std::fs::read_dir(list_or_dir)
            .with_context(|| format!("{}: cannot list", list_or_dir.display()))?
            .filter_map(|e| e.ok())
            .filter(|e| e.path().is_file())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| {
                Path::new(n)
                    .extension()
                    .and_then(|x| x.to_str())
                    .is_some_and(|x| IMAGE_EXTENSIONS.contains(&x.to_ascii_lowercase().as_str()))
            })
            .collect();
        names.sort_by(|a, b| natural_cmp(a, b));
        names
            .into_iter()
            .map(|name| ImageRef {
                path: list_or_dir.join(&name),
                name,
            })
            .collect()
    } else {
        let text = std::fs::read_to_string(list_or_dir)
            .with_context(|| format!("{}: cannot read image list", list_or_dir.display()))?;
        let base = list_or_dir.parent().unwrap_or(Path::new("."));
        text.lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
            .map(|l| ImageRef {
                name: l.to_owned(),
                path: base.join(l),
            })
            .collect()
    };
    if images.is_empty() {
        bail!("{}: no images listed", list_or_dir.display());
    }
    Ok(images)
}

/// Order names so that "Image10" follows "Image9".
fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    fn key(s: &str) -> Vec<(String, u64)> {
        let mut out = Vec::new();
        let mut text = String::new();
        let mut digits = String::new();
        for c in s.chars() {
            if c.is_ascii_digit() {
                digits.push(c);
            } else {
                if !digits.is_empty() {
                    out.push((std::mem::take(&mut text), digits.parse().unwrap_or(u64::MAX)));
                    digits.clear();
                }
                text.push(c);
            }
        }
        out.push((text, digits.parse().unwrap_or(0)));
        out
    }
    key(a).cmp(&key(b)).then_with(|| a.cmp(b))
}

/// A dataset folder in the shared layout.
#[derive(Debug, Clone)]
pub struct Dataset {
    pub root: PathBuf,
    pub name: String,
    pub map: Vec<ImageRef>,
    pub queries: Vec<ImageRef>,
    /// For each query index, the map ids that are correct matches.
    pub truth: Vec<HashSet<u32>>,
}

impl Dataset {
    pub fn open(root: &Path) -> anyhow::Result<Self> {
        let map = image_list(&root.join("map.txt"))?;
        let queries = image_list(&root.join("queries.txt"))?;
        let map_ids: HashMap<&str, u32> = map
            .iter()
            .enumerate()
            .map(|(i, r)| (r.name.as_str(), i as u32))
            .collect();
        let query_ids: HashMap<&str, usize> = queries
            .iter()
            .enumerate()
            .map(|(i, r)| (r.name.as_str(), i))
            .collect();
        let gt_path = root.join("ground_truth.csv");
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_path(&gt_path)
            .with_context(|| format!("{}: cannot read", gt_path.display()))?;
        let mut truth = vec![HashSet::new(); queries.len()];
        for (line, row) in reader.records().enumerate() {
            let row = row.with_context(|| format!("{}: row {}", gt_path.display(), line + 2))?;
            let (q, m) = (row.get(0).unwrap_or(""), row.get(1).unwrap_or(""));
            let (Some(&qi), Some(&mi)) = (query_ids.get(q), map_ids.get(m)) else {
                bail!(
                    "{}: row {}: `{q},{m}` names an image not in queries.txt / map.txt",
                    gt_path.display(),
                    line + 2
                );
            };
            truth[qi].insert(mi);
        }
        let name = root
            .canonicalize()
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .unwrap_or_else(|| root.display().to_string());
        Ok(Self {
            root: root.to_path_buf(),
            name,
            map,
            queries,
            truth,
        })
    }

    /// Queries that have at least one match in the map.
    pub fn queries_with_match(&self) -> usize {
        self.truth.iter().filter(|t| !t.is_empty()).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order() {
        let mut v = vec!["Image10.jpg", "Image9.jpg", "Image100.jpg", "Image1.jpg"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, ["Image1.jpg", "Image9.jpg", "Image10.jpg", "Image100.jpg"]);
    }

    #[test]
    fn list_file_paths_are_relative_to_the_list() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("l.txt"), "# c\na/1.jpg\n\n b.png \n").unwrap();
        let l = image_list(&dir.path().join("l.txt")).unwrap();
        assert_eq!(l.len(), 2);
        assert_eq!(l[0].name, "a/1.jpg");
        assert_eq!(l[0].path, dir.path().join("a/1.jpg"));
        assert_eq!(l[1].name, "b.png");
        std::fs::write(dir.path().join("e.txt"), "\n").unwrap();
        assert!(image_list(&dir.path().join("e.txt")).is_err());
        assert!(image_list(&dir.path().join("missing.txt")).is_err());
    }
}
