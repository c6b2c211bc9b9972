//! Per-image metadata: names, place labels and poses, and the places CSV they
//! come from. Strings live in flat tables (offsets + UTF-8 bytes) so a map of
//! millions of images loads without parsing.

use super::MapView;
use serde::Serialize;
use std::collections::HashMap;
use std::path::Path;

/// Owned string table.
#[derive(Debug, Clone, Default)]
pub struct StringTable {
    pub offsets: Vec<u64>,
    pub bytes: Vec<u8>,
}

impl StringTable {
    pub fn from_strings<S: AsRef<str>>(strings: impl IntoIterator<Item = S>) -> Self {
        let mut t = Self {
            offsets: vec![0],
            bytes: Vec::new(),
        };
        for s in strings {
            t.bytes.extend_from_slice(s.as_ref().as_bytes());
            t.offsets.push(t.bytes.len() as u64);
        }
        t
    }

    pub fn as_view(&self) -> StrTable<'_> {
        StrTable {
            offsets: &self.offsets,
            bytes: &self.bytes,
        }
    }
}

/// Borrowed string table.
#[derive(Debug, Clone, Copy)]
pub struct StrTable<'a> {
    pub offsets: &'a [u64],
    pub bytes: &'a [u8],
}

impl<'a> StrTable<'a> {
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// String `i`; "" when out of range.
    pub fn get(&self, i: usize) -> &'a str {
        let (Some(&a), Some(&b)) = (self.offsets.get(i), self.offsets.get(i + 1)) else {
            return "";
        };
        self.bytes
            .get(a as usize..b as usize)
            .and_then(|s| std::str::from_utf8(s).ok())
            .unwrap_or("")
    }

    /// Offsets ascend, stay inside the bytes, and every string is UTF-8.
    pub fn validate(&self) -> Result<(), String> {
        if self.offsets.first() != Some(&0) {
            return Err("string table does not start at 0".into());
        }
        if self.offsets.windows(2).any(|w| w[0] > w[1])
            || *self.offsets.last().unwrap_or(&0) != self.bytes.len() as u64
        {
            return Err("string table offsets are inconsistent".into());
        }
        std::str::from_utf8(self.bytes).map_err(|e| format!("string table is not UTF-8: {e}"))?;
        Ok(())
    }
}

/// What the map knows about one image.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ImageInfo<'a> {
    pub id: u32,
    pub name: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub place: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose: Option<HashMap<&'a str, f64>>,
}

pub(super) fn image_info<'a>(
    view: &MapView<'a>,
    pose_fields: &'a [String],
    id: u32,
) -> ImageInfo<'a> {
    let i = id as usize;
    let place = Some(view.places.get(i)).filter(|p| !p.is_empty());
    let p = pose_fields.len();
    let pose = view
        .poses
        .get(i * p..(i + 1) * p)
        .and_then(|row| pose_of(pose_fields, row));
    ImageInfo {
        id,
        name: view.names.get(i),
        place,
        pose,
    }
}

/// The known (finite) values of a pose row by field name; `None` when none is.
pub fn pose_of<'a>(pose_fields: &'a [String], row: &[f64]) -> Option<HashMap<&'a str, f64>> {
    let known: HashMap<&str, f64> = pose_fields
        .iter()
        .zip(row)
        .filter(|(_, v)| v.is_finite())
        .map(|(k, &v)| (k.as_str(), v))
        .collect();
    (!known.is_empty()).then_some(known)
}

/// A pose value as text gives it (a query parameter, `--pose`, a places CSV
/// cell): a finite number, blanks around it ignored.
pub fn parse_pose_value(v: &str) -> Option<f64> {
    v.trim().parse::<f64>().ok().filter(|x| x.is_finite())
}

/// The map's pose fields, as an error names them.
fn pose_fields(known: &[String]) -> String {
    if known.is_empty() {
        "it has none: it was built without poses".to_owned()
    } else {
        format!("its pose fields: {}", known.join(", "))
    }
}

/// Why a pose given field by field was refused; each names its field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseError {
    #[error("given more than once")]
    Repeated { field: String },
    #[error("not a pose field of the map ({})", pose_fields(known))]
    Unknown { field: String, known: Vec<String> },
    #[error("`{value}` is not a finite number")]
    NotFinite { field: String, value: String },
}

impl PoseError {
    /// The field the error is about.
    pub fn field(&self) -> &str {
        match self {
            Self::Repeated { field }
            | Self::Unknown { field, .. }
            | Self::NotFinite { field, .. } => field,
        }
    }
}

/// An image's pose row from `(field, value)` pairs, in the order of the
/// map's `pose_fields`: NaN (unknown) for a field not given, and empty when
/// none is given. A field given twice, a name that is not a pose field, or a
/// value [`parse_pose_value`] refuses is an error.
pub fn pose_row<'a>(
    pose_fields: &[String],
    given: impl IntoIterator<Item = (&'a str, &'a str)>,
) -> Result<Vec<f64>, PoseError> {
    let mut row = vec![f64::NAN; pose_fields.len()];
    let mut any = false;
    for (field, value) in given {
        let Some(i) = pose_fields.iter().position(|f| f == field) else {
            return Err(PoseError::Unknown {
                field: field.to_owned(),
                known: pose_fields.to_vec(),
            });
        };
        if !row[i].is_nan() {
            return Err(PoseError::Repeated {
                field: field.to_owned(),
            });
        }
        row[i] = parse_pose_value(value).ok_or_else(|| PoseError::NotFinite {
            field: field.to_owned(),
            value: value.to_owned(),
        })?;
        any = true;
    }
    Ok(if any { row } else { Vec::new() })
}

/// Place labels and poses for map images, read from a CSV whose header is
/// `image,place[,pose fields...]`; `image` is the image's name as listed in
/// the map's image list, or its id.
#[derive(Debug, Clone, Default)]
pub struct Places {
    pub pose_fields: Vec<String>,
    /// image key → (place, pose values)
    pub rows: HashMap<String, (String, Vec<f64>)>,
}

impl Places {
    pub fn from_csv(path: &Path) -> anyhow::Result<Self> {
        use anyhow::Context;
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_path(path)
            .with_context(|| format!("{}: cannot read places CSV", path.display()))?;
        let header = reader.headers()?.clone();
        if header.get(0) != Some("image") || header.get(1) != Some("place") {
            anyhow::bail!(
                "{}: header must start with `image,place` (then optional pose fields), found `{}`",
                path.display(),
                header.iter().collect::<Vec<_>>().join(",")
            );
        }
        let pose_fields: Vec<String> = header.iter().skip(2).map(str::to_owned).collect();
        let mut rows = HashMap::new();
        for (line, record) in reader.records().enumerate() {
            let record = record.with_context(|| format!("{}: row {}", path.display(), line + 2))?;
            let image = record.get(0).unwrap_or_default().to_owned();
            let place = record.get(1).unwrap_or_default().to_owned();
            let pose = (2..header.len())
                .map(|i| {
                    let v = record.get(i).unwrap_or("");
                    if v.is_empty() {
                        Ok(f64::NAN)
                    } else {
                        parse_pose_value(v).with_context(|| {
                            format!(
                                "{}: row {}: `{v}` is not a finite number",
                                path.display(),
                                line + 2
                            )
                        })
                    }
                })
                .collect::<anyhow::Result<Vec<f64>>>()?;
            rows.insert(image, (place, pose));
        }
        Ok(Self { pose_fields, rows })
    }

    /// Place and pose of the image with this name and id, if listed.
    pub fn lookup(&self, name: &str, id: usize) -> Option<&(String, Vec<f64>)> {
        self.rows
            .get(name)
            .or_else(|| self.rows.get(&id.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_rows() {
        let fields = vec!["x".to_owned(), "y".to_owned()];
        let row = pose_row(&fields, [("y", " 2.5 ")]).unwrap();
        assert!(row[0].is_nan());
        assert_eq!(row[1], 2.5);
        assert_eq!(pose_row(&fields, []).unwrap(), Vec::<f64>::new());
        let e = pose_row(&fields, [("x", "1"), ("x", "2")]).unwrap_err();
        assert_eq!(e, PoseError::Repeated { field: "x".into() });
        let e = pose_row(&fields, [("z", "1")]).unwrap_err();
        assert_eq!(e.field(), "z");
        assert!(e.to_string().contains("its pose fields: x, y"), "{e}");
        let e = pose_row(&[], [("x", "1")]).unwrap_err();
        assert!(e.to_string().contains("built without poses"), "{e}");
        for bad in ["abc", "inf", "NaN", ""] {
            let e = pose_row(&fields, [("x", bad)]).unwrap_err();
            assert!(matches!(e, PoseError::NotFinite { .. }), "{bad}");
        }
    }
}
