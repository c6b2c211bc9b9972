//! Opening a store file: map it, validate its structure, hand out typed sections.

use super::{ALIGN, Dtype, ENTRY_LEN, HEADER_LEN, NAME_LEN, StoreError, checksum};
use memmap2::Mmap;
use std::path::{Path, PathBuf};

/// One entry of the section table.
#[derive(Debug, Clone)]
pub struct Section {
    pub name: String,
    pub dtype: Dtype,
    pub offset: usize,
    pub len: usize,
    pub checksum: u64,
}

/// A validated, memory-mapped store file.
pub struct Store {
    path: PathBuf,
    map: Mmap,
    sections: Vec<Section>,
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Store").field("path", &self.path).finish()
    }
}

impl Store {
    /// Map `path` and check that it is a `kind` file (`magic`) of `version`.
    /// With `verify`, every section's checksum is recomputed.
    pub fn open(
        path: &Path,
        magic: [u8; 8],
        kind: &'static str,
        version: u32,
        verify: bool,
    ) -> Result<Self, StoreError> {
        let file = std::fs::File::open(path).map_err(|e| StoreError::io(path, e))?;
        // SAFETY: the mapping is read-only; files are replaced by rename, never
        // rewritten in place, so the mapped bytes do not change under us.
        let map = unsafe { Mmap::map(&file) }.map_err(|e| StoreError::io(path, e))?;
        let corrupt = |detail: String| StoreError::Corrupt {
            path: path.to_path_buf(),
            detail,
        };
        if map.len() < HEADER_LEN {
            if map.len() >= 8 && map[..8] != magic {
                return Err(wrong_magic(path, kind, &map[..8]));
            }
            return Err(corrupt(format!(
                "{} bytes, shorter than a header",
                map.len()
            )));
        }
        if map[..8] != magic {
            return Err(wrong_magic(path, kind, &map[..8]));
        }
        let found_version = u32_at(&map, 8);
        if found_version != version {
            return Err(StoreError::WrongVersion {
                path: path.to_path_buf(),
                found: found_version,
                expected: version,
            });
        }
        let count = u32_at(&map, 12) as usize;
        let table_end = count
            .checked_mul(ENTRY_LEN)
            .and_then(|n| n.checked_add(HEADER_LEN))
            .filter(|&end| end <= map.len())
            .ok_or_else(|| {
                corrupt(format!(
                    "section table of {count} entries runs past the end"
                ))
            })?;
        let table = &map[HEADER_LEN..table_end];
        if checksum(table) != u64_at(&map, 16) {
            return Err(StoreError::Checksum {
                path: path.to_path_buf(),
                section: "<table>".into(),
            });
        }
        let mut sections = Vec::with_capacity(count);
        for entry in table.chunks_exact(ENTRY_LEN) {
            let name_bytes = &entry[..NAME_LEN];
            let name_end = name_bytes.iter().position(|&b| b == 0).unwrap_or(NAME_LEN);
            let name = String::from_utf8_lossy(&name_bytes[..name_end]).into_owned();
            let dtype = Dtype::from_u32(u32_at(entry, NAME_LEN))
                .ok_or_else(|| corrupt(format!("section '{name}' has an unknown type")))?;
            let offset = u64_at(entry, NAME_LEN + 8);
            let len = u64_at(entry, NAME_LEN + 16);
            let end = offset.checked_add(len);
            if end.is_none_or(|end| end > map.len() as u64)
                || !offset.is_multiple_of(ALIGN as u64)
                || !len.is_multiple_of(dtype.size() as u64)
            {
                return Err(corrupt(format!(
                    "section '{name}' (offset {offset}, {len} bytes) does not fit a {} byte file",
                    map.len()
                )));
            }
            sections.push(Section {
                name,
                dtype,
                offset: offset as usize,
                len: len as usize,
                checksum: u64_at(entry, NAME_LEN + 24),
            });
        }
        let store = Self {
            path: path.to_path_buf(),
            map,
            sections,
        };
        if verify {
            store.verify()?;
        }
        Ok(store)
    }

    /// Recompute every section's checksum.
    pub fn verify(&self) -> Result<(), StoreError> {
        use rayon::prelude::*;
        self.sections.par_iter().try_for_each(|s| {
            if checksum(&self.map[s.offset..s.offset + s.len]) == s.checksum {
                Ok(())
            } else {
                Err(StoreError::Checksum {
                    path: self.path.clone(),
                    section: s.name.clone(),
                })
            }
        })
    }

    /// The checksum of the section table, which holds every section's
    /// checksum: it identifies the file's content.
    pub fn table_checksum(&self) -> u64 {
        u64_at(&self.map, 16)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn section(&self, name: &str) -> Result<&Section, StoreError> {
        self.sections
            .iter()
            .find(|s| s.name == name)
            .ok_or_else(|| StoreError::MissingSection {
                path: self.path.clone(),
                section: name.to_owned(),
            })
    }

    fn typed(&self, name: &str, dtype: Dtype) -> Result<&[u8], StoreError> {
        let s = self.section(name)?;
        if s.dtype != dtype {
            return Err(self.invalid(format!(
                "section '{name}' holds {:?}, expected {dtype:?}",
                s.dtype
            )));
        }
        Ok(&self.map[s.offset..s.offset + s.len])
    }

    pub fn bytes(&self, name: &str) -> Result<&[u8], StoreError> {
        self.typed(name, Dtype::Bytes)
    }

    pub fn f32s(&self, name: &str) -> Result<&[f32], StoreError> {
        Ok(bytemuck::cast_slice(self.typed(name, Dtype::F32)?))
    }

    pub fn u32s(&self, name: &str) -> Result<&[u32], StoreError> {
        Ok(bytemuck::cast_slice(self.typed(name, Dtype::U32)?))
    }

    pub fn u64s(&self, name: &str) -> Result<&[u64], StoreError> {
        Ok(bytemuck::cast_slice(self.typed(name, Dtype::U64)?))
    }

    pub fn f64s(&self, name: &str) -> Result<&[f64], StoreError> {
        Ok(bytemuck::cast_slice(self.typed(name, Dtype::F64)?))
    }

    /// A JSON section parsed into `T`.
    pub fn json<T: serde::de::DeserializeOwned>(&self, name: &str) -> Result<T, StoreError> {
        serde_json::from_slice(self.bytes(name)?)
            .map_err(|e| self.invalid(format!("section '{name}' is not valid: {e}")))
    }

    /// An error about this file's contents.
    pub fn invalid(&self, detail: impl Into<String>) -> StoreError {
        StoreError::Invalid {
            path: self.path.clone(),
            detail: detail.into(),
        }
    }
}

fn wrong_magic(path: &Path, kind: &'static str, found: &[u8]) -> StoreError {
    StoreError::WrongMagic {
        path: path.to_path_buf(),
        expected: kind,
        found: String::from_utf8_lossy(found).into_owned(),
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}
