//! TensorBoard event files (`events.out.tfevents.*`), so that `tensorboard --logdir runs`
//! shows rlnav's training curves as it does rl_games'. The protobuf messages are declared
//! with prost (field numbers from TensorFlow's `event.proto` and `summary.proto`) and the
//! checksums are crc32c's; only the TFRecord framing is written here.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// `tensorflow.Event` (the fields rlnav writes).
#[derive(Clone, PartialEq, prost::Message)]
pub struct Event {
    /// Seconds since the epoch.
    #[prost(double, tag = "1")]
    pub wall_time: f64,
    /// Global step.
    #[prost(int64, tag = "2")]
    pub step: i64,
    /// `brain.Event:2` in the first event of a file.
    #[prost(string, optional, tag = "3")]
    pub file_version: Option<String>,
    /// Scalar summaries.
    #[prost(message, optional, tag = "5")]
    pub summary: Option<Summary>,
}

/// `tensorflow.Summary`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Summary {
    /// Values.
    #[prost(message, repeated, tag = "1")]
    pub value: Vec<SummaryValue>,
}

/// `tensorflow.Summary.Value` with a simple (scalar) value.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SummaryValue {
    /// Curve name.
    #[prost(string, tag = "1")]
    pub tag: String,
    /// Value.
    #[prost(float, optional, tag = "2")]
    pub simple_value: Option<f32>,
}

fn masked_crc(data: &[u8]) -> u32 {
    let c = crc32c::crc32c(data);
    c.rotate_right(15).wrapping_add(0xa282_ead8)
}

/// Appends scalar events to a TensorBoard event file in a log folder.
pub struct EventWriter {
    out: BufWriter<File>,
    path: PathBuf,
}

fn now() -> f64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}

impl EventWriter {
    /// Creates a new `logdir/events.out.tfevents.<seconds>.rlnav.<pid>.<nanos>` (never an
    /// existing file: a resumed run adds a file) and writes the version record.
    pub fn create(logdir: &Path) -> io::Result<Self> {
        std::fs::create_dir_all(logdir)?;
        let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        let name = format!("events.out.tfevents.{}.rlnav.{}.{}", t.as_secs(), std::process::id(), t.subsec_nanos());
        let path = logdir.join(name);
        let mut w = Self { out: BufWriter::new(File::create_new(&path)?), path };
        w.event(&Event { wall_time: now(), step: 0, file_version: Some("brain.Event:2".into()), summary: None })?;
        Ok(w)
    }

    /// The file written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn event(&mut self, e: &Event) -> io::Result<()> {
        let data = prost::Message::encode_to_vec(e);
        let len = (data.len() as u64).to_le_bytes();
        self.out.write_all(&len)?;
        self.out.write_all(&masked_crc(&len).to_le_bytes())?;
        self.out.write_all(&data)?;
        self.out.write_all(&masked_crc(&data).to_le_bytes())
    }

    /// Writes scalars `(tag, value)` at `step` and flushes.
    pub fn scalars(&mut self, step: i64, values: &[(&str, f32)]) -> io::Result<()> {
        let summary = Summary {
            value: values.iter().map(|(t, v)| SummaryValue { tag: t.to_string(), simple_value: Some(*v) }).collect(),
        };
        self.event(&Event { wall_time: now(), step, file_version: None, summary: Some(summary) })?;
        self.out.flush()
    }
}

/// Reads back the scalar events of a file: `(step, tag, value)` (checks every checksum).
pub fn read_scalars(path: &Path) -> io::Result<Vec<(i64, String, f32)>> {
    let bytes = std::fs::read(path)?;
    let bad = |m: &str| io::Error::new(io::ErrorKind::InvalidData, format!("{}: {m}", path.display()));
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        if at + 12 > bytes.len() {
            return Err(bad("truncated record header"));
        }
        let len_bytes = &bytes[at..at + 8];
        let len = u64::from_le_bytes(len_bytes.try_into().expect("8 bytes")) as usize;
        let crc = u32::from_le_bytes(bytes[at + 8..at + 12].try_into().expect("4 bytes"));
        if crc != masked_crc(len_bytes) {
            return Err(bad("bad length checksum"));
        }
        let data = bytes.get(at + 12..at + 12 + len).ok_or_else(|| bad("truncated record"))?;
        let crc = bytes.get(at + 12 + len..at + 16 + len).ok_or_else(|| bad("truncated record"))?;
        if u32::from_le_bytes(crc.try_into().expect("4 bytes")) != masked_crc(data) {
            return Err(bad("bad data checksum"));
        }
        let e: Event = prost::Message::decode(data).map_err(|e| bad(&e.to_string()))?;
        for v in e.summary.map(|s| s.value).unwrap_or_default() {
            if let Some(x) = v.simple_value {
                out.push((e.step, v.tag, x));
            }
        }
        at += 16 + len;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_matches_tensorflow() {
        // crc32c (Castagnoli) check value, and the masked CRC of nothing (just the mask delta).
        assert_eq!(crc32c::crc32c(b"123456789"), 0xe306_9283, "Castagnoli check value");
        assert_eq!(masked_crc(b""), 0xa282_ead8);
    }

    #[test]
    fn round_trip() {
        let dir = std::env::temp_dir().join(format!("rlnav-tb-{}", std::process::id()));
        let mut w = EventWriter::create(&dir).unwrap();
        w.scalars(1, &[("reward", 1.5), ("success", 0.25)]).unwrap();
        w.scalars(2, &[("reward", 2.5)]).unwrap();
        let got = read_scalars(w.path()).unwrap();
        assert_eq!(got, vec![(1, "reward".into(), 1.5), (1, "success".into(), 0.25), (2, "reward".into(), 2.5)]);
        std::fs::remove_dir_all(dir).ok();
    }
}
