//! Building a store file in memory section by section and writing it atomically.

use super::atomic::write_atomic;
use super::{ALIGN, Dtype, ENTRY_LEN, HEADER_LEN, NAME_LEN, StoreError, checksum};
use std::borrow::Cow;
use std::path::Path;

struct PendingSection<'a> {
    name: String,
    dtype: Dtype,
    bytes: Cow<'a, [u8]>,
}

/// Collects sections, then writes header, table and payload in one pass.
pub struct StoreWriter<'a> {
    magic: [u8; 8],
    version: u32,
    sections: Vec<PendingSection<'a>>,
}

impl<'a> StoreWriter<'a> {
    pub fn new(magic: [u8; 8], version: u32) -> Self {
        Self {
            magic,
            version,
            sections: Vec::new(),
        }
    }

    fn push(&mut self, name: &str, dtype: Dtype, bytes: Cow<'a, [u8]>) -> &mut Self {
        assert!(name.len() <= NAME_LEN, "section name too long: {name}");
        self.sections.push(PendingSection {
            name: name.to_owned(),
            dtype,
            bytes,
        });
        self
    }

    pub fn bytes(&mut self, name: &str, bytes: &'a [u8]) -> &mut Self {
        self.push(name, Dtype::Bytes, Cow::Borrowed(bytes))
    }

    pub fn owned_bytes(&mut self, name: &str, bytes: Vec<u8>) -> &mut Self {
        self.push(name, Dtype::Bytes, Cow::Owned(bytes))
    }

    pub fn f32s(&mut self, name: &str, values: &'a [f32]) -> &mut Self {
        self.push(
            name,
            Dtype::F32,
            Cow::Borrowed(bytemuck::cast_slice(values)),
        )
    }

    pub fn u32s(&mut self, name: &str, values: &'a [u32]) -> &mut Self {
        self.push(
            name,
            Dtype::U32,
            Cow::Borrowed(bytemuck::cast_slice(values)),
        )
    }

    pub fn u64s(&mut self, name: &str, values: &'a [u64]) -> &mut Self {
        self.push(
            name,
            Dtype::U64,
            Cow::Borrowed(bytemuck::cast_slice(values)),
        )
    }

    pub fn f64s(&mut self, name: &str, values: &'a [f64]) -> &mut Self {
        self.push(
            name,
            Dtype::F64,
            Cow::Borrowed(bytemuck::cast_slice(values)),
        )
    }

    /// A JSON document as a bytes section.
    pub fn json<T: serde::Serialize>(&mut self, name: &str, value: &T) -> &mut Self {
        let bytes = serde_json::to_vec(value).expect("metadata serializes");
        self.owned_bytes(name, bytes)
    }

    /// Write to `path` atomically ([`write_atomic`]): readers see the old file
    /// or the new one, never a torn one. Returns the checksum of each section,
    /// in insertion order.
    pub fn write_atomic(&self, path: &Path) -> Result<Vec<u64>, StoreError> {
        // Test knob: pause between sections so a test can kill a writer mid-file.
        let pause = std::env::var("BOWLOC_WRITE_DELAY_MS")
            .ok()
            .and_then(|v| v.parse().ok())
            .map(std::time::Duration::from_millis);

        let sums: Vec<u64> = self.sections.iter().map(|s| checksum(&s.bytes)).collect();
        let table_len = self.sections.len() * ENTRY_LEN;
        let mut offset = align_up(HEADER_LEN + table_len);
        let mut table = Vec::with_capacity(table_len);
        for (section, sum) in self.sections.iter().zip(&sums) {
            let mut name = [0u8; NAME_LEN];
            name[..section.name.len()].copy_from_slice(section.name.as_bytes());
            table.extend_from_slice(&name);
            table.extend_from_slice(&(section.dtype as u32).to_le_bytes());
            table.extend_from_slice(&0u32.to_le_bytes());
            table.extend_from_slice(&(offset as u64).to_le_bytes());
            table.extend_from_slice(&(section.bytes.len() as u64).to_le_bytes());
            table.extend_from_slice(&sum.to_le_bytes());
            offset = align_up(offset + section.bytes.len());
        }

        write_atomic(path, |out| {
            out.write_all(&self.magic)?;
            out.write_all(&self.version.to_le_bytes())?;
            out.write_all(&(self.sections.len() as u32).to_le_bytes())?;
            out.write_all(&checksum(&table).to_le_bytes())?;
            out.write_all(&table)?;
            let mut written = HEADER_LEN + table.len();
            for section in &self.sections {
                let pad = align_up(written) - written;
                out.write_all(&[0u8; ALIGN][..pad])?;
                out.write_all(&section.bytes)?;
                written += pad + section.bytes.len();
                if let Some(pause) = pause {
                    out.flush()?;
                    std::thread::sleep(pause);
                }
            }
            Ok(())
        })?;
        Ok(sums)
    }
}

fn align_up(n: usize) -> usize {
    n.div_ceil(ALIGN) * ALIGN
}
