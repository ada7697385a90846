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
    /// existing file: a resumed run adds a file) and writes the version record. The
    /// nanoseconds have nine digits, so that two sessions of one process within a second sort
    /// by name in the order they started (TensorBoard reads files in name order).
    pub fn create(logdir: &Path) -> io::Result<Self> {
        std::fs::create_dir_all(logdir)?;
        let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        let name = format!("events.out.tfevents.{}.rlnav.{}.{:09}", t.as_secs(), std::process::id(), t.subsec_nanos());
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

/// One TFRecord of an event file: the decoded event and the record's bytes as written.
struct Record<'a> {
    event: Event,
    bytes: &'a [u8],
}

/// Splits an event file into records, checking every checksum. A record cut short at the end
/// of the file (a process killed while writing it) is an error unless `allow_cut_tail`, where
/// it ends the list.
fn records<'a>(path: &Path, bytes: &'a [u8], allow_cut_tail: bool) -> io::Result<Vec<Record<'a>>> {
    let bad = |m: &str| io::Error::new(io::ErrorKind::InvalidData, format!("{}: {m}", path.display()));
    let mut out = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        if at + 12 > bytes.len() {
            if allow_cut_tail {
                break;
            }
            return Err(bad("truncated record header"));
        }
        let len_bytes = &bytes[at..at + 8];
        let len = u64::from_le_bytes(len_bytes.try_into().expect("8 bytes")) as usize;
        let crc = u32::from_le_bytes(bytes[at + 8..at + 12].try_into().expect("4 bytes"));
        if crc != masked_crc(len_bytes) {
            return Err(bad("bad length checksum"));
        }
        let end = at.saturating_add(16).saturating_add(len);
        if end > bytes.len() {
            if allow_cut_tail {
                break;
            }
            return Err(bad("truncated record"));
        }
        let data = &bytes[at + 12..at + 12 + len];
        if u32::from_le_bytes(bytes[end - 4..end].try_into().expect("4 bytes")) != masked_crc(data) {
            return Err(bad("bad data checksum"));
        }
        let event: Event = prost::Message::decode(data).map_err(|e| bad(&e.to_string()))?;
        out.push(Record { event, bytes: &bytes[at..end] });
        at = end;
    }
    Ok(out)
}

/// Reads back the scalar events of a file: `(step, tag, value)` (checks every checksum).
pub fn read_scalars(path: &Path) -> io::Result<Vec<(i64, String, f32)>> {
    let bytes = std::fs::read(path)?;
    let mut out = Vec::new();
    for r in records(path, &bytes, false)? {
        for v in r.event.summary.map(|s| s.value).unwrap_or_default() {
            if let Some(x) = v.simple_value {
                out.push((r.event.step, v.tag, x));
            }
        }
    }
    Ok(out)
}

/// The event files of `logdir` (TensorBoard reads every file whose name contains
/// `tfevents`), in name order; none when the folder does not exist.
pub fn event_files(logdir: &Path) -> io::Result<Vec<PathBuf>> {
    let entries = match std::fs::read_dir(logdir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e),
    };
    let mut files = Vec::new();
    for entry in entries {
        let path = entry?.path();
        if path.is_file() && path.file_name().is_some_and(|n| n.to_string_lossy().contains("tfevents")) {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

/// Removes from every event file in `logdir` the events whose step is past `last_step`, and
/// a record cut short by a killed process; returns how many events went.
///
/// A resumed run writes the steps after its checkpoint again, in a new file, and TensorBoard
/// would show both copies of those steps: for `brain.Event:2` files its reader purges
/// orphaned steps only at a second `SessionLog.START` event, and other event-file readers
/// never do. So the old copies are removed from the files themselves.
/// Each changed file is rewritten whole under a temporary name (without `tfevents`, so that
/// TensorBoard never reads it half-written) and renamed over the old one; records are kept
/// byte for byte.
pub fn drop_events_after(logdir: &Path, last_step: i64) -> io::Result<usize> {
    let mut dropped = 0;
    for path in event_files(logdir)? {
        let bytes = std::fs::read(&path)?;
        let all = records(&path, &bytes, true)?;
        let kept: Vec<&Record> = all.iter().filter(|r| r.event.step <= last_step).collect();
        let kept_len: usize = kept.iter().map(|r| r.bytes.len()).sum();
        if kept_len == bytes.len() {
            continue;
        }
        dropped += all.len() - kept.len();
        let tmp = logdir.join(format!(".rlnav-rewrite.{}", std::process::id()));
        let mut out = BufWriter::new(File::create(&tmp)?);
        for r in &kept {
            out.write_all(r.bytes)?;
        }
        out.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        std::fs::rename(&tmp, &path)?;
    }
    Ok(dropped)
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
    fn files_of_one_second_sort_in_creation_order() {
        let dir = std::env::temp_dir().join(format!("rlnav-tb-order-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let made: Vec<PathBuf> = (0..20).map(|_| EventWriter::create(&dir).unwrap().path().to_path_buf()).collect();
        assert_eq!(event_files(&dir).unwrap(), made, "name order is creation order");
        std::fs::remove_dir_all(dir).ok();
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

    #[test]
    fn dropping_events_past_a_step_keeps_the_rest_and_a_cut_tail_goes() {
        let dir = std::env::temp_dir().join(format!("rlnav-tb-drop-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut w = EventWriter::create(&dir).unwrap();
        for step in 1..=5 {
            w.scalars(step * 10, &[("reward", step as f32)]).unwrap();
        }
        let path = w.path().to_path_buf();
        drop(w);
        // A killed writer leaves half a record.
        let mut f = std::fs::OpenOptions::new().append(true).open(&path).unwrap();
        f.write_all(&[7, 0, 0, 0, 0, 0]).unwrap();
        drop(f);
        assert!(read_scalars(&path).is_err(), "the cut record is seen");
        assert_eq!(drop_events_after(&dir, 30).unwrap(), 2);
        let got = read_scalars(&path).unwrap();
        assert_eq!(got, vec![(10, "reward".into(), 1.0), (20, "reward".into(), 2.0), (30, "reward".into(), 3.0)]);
        // The version record (step 0) stays first; nothing else to drop the second time.
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(records(&path, &bytes, false).unwrap()[0].event.file_version.as_deref(), Some("brain.Event:2"));
        assert_eq!(drop_events_after(&dir, 30).unwrap(), 0);
        assert_eq!(event_files(&dir).unwrap(), vec![path.clone()]);
        // A corrupt record is an error naming the file, not silently dropped.
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 0xff;
        std::fs::write(&path, bytes).unwrap();
        let e = drop_events_after(&dir, 0).unwrap_err().to_string();
        assert!(e.contains("tfevents") && e.contains("checksum"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }
}
