//! Episodes recorded as MCAP files in rosbag2's layout (profile `ros2`, `ros2msg` schemas,
//! CDR messages), so that Foxglove, `ros2 bag play` and any MCAP reader open them: `/scan`,
//! `/odom`, `/tf`, `/cmd_vel`, `/goal_pose` and `/clock`, one message of each per control
//! step, stamped with simulated time.

use rlnav_msgs::msg::{self, Clock, RosMessage, to_cdr};
use rlnav_msgs::sim_topics::{Frames, SimMessages};
use rlnav_sim::{Controller, EpisodeStats, NavEnv};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::evaluate::EpisodeTrace;

/// Errors writing a recording.
#[derive(Debug, thiserror::Error)]
#[error("recording {file}: {message}")]
pub struct RecordError {
    /// The MCAP file.
    pub file: PathBuf,
    /// What failed.
    pub message: String,
}

/// The QoS rosbag2 stores per channel so that `ros2 bag play` offers what the robot offered:
/// sensor data is best effort, everything else reliable (keep last 10 either way).
fn offered_qos(reliable: bool, transient: bool) -> String {
    format!(
        "- history: 3\n  depth: 0\n  reliability: {}\n  durability: {}\n  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n  avoid_ros_namespace_conventions: false\n",
        if reliable { 1 } else { 2 },
        if transient { 1 } else { 2 }
    )
}

/// An MCAP file being written, one channel per topic.
pub struct McapRecorder {
    file: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    channels: BTreeMap<&'static str, u16>,
    sequence: u32,
}

impl McapRecorder {
    /// Creates `file` (and its folder) with the channels of a simulated robot.
    pub fn create(file: &Path) -> Result<Self, RecordError> {
        let err = |message: String| RecordError { file: file.to_path_buf(), message };
        if let Some(dir) = file.parent() {
            std::fs::create_dir_all(dir).map_err(|e| err(format!("creating {}: {e}", dir.display())))?;
        }
        let f = File::create(file).map_err(|e| err(e.to_string()))?;
        // zstd chunks at a fast level, written on this thread (an episode's chunks are small).
        let opts = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("rlnav ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(1)
            .compression_threads(0);
        let writer = opts.create(BufWriter::new(f)).map_err(|e| err(e.to_string()))?;
        let mut r = Self { file: file.to_path_buf(), writer, channels: BTreeMap::new(), sequence: 0 };
        r.channel::<msg::LaserScan>("/scan", false, false)?;
        r.channel::<msg::Odometry>("/odom", true, false)?;
        r.channel::<msg::TFMessage>("/tf", true, false)?;
        r.channel::<msg::Twist>("/cmd_vel", true, false)?;
        r.channel::<msg::PoseStamped>("/goal_pose", true, false)?;
        r.channel::<Clock>("/clock", true, false)?;
        Ok(r)
    }

    fn err(&self, e: impl std::fmt::Display) -> RecordError {
        RecordError { file: self.file.clone(), message: e.to_string() }
    }

    fn channel<M: RosMessage>(
        &mut self,
        topic: &'static str,
        reliable: bool,
        transient: bool,
    ) -> Result<(), RecordError> {
        let schema =
            self.writer.add_schema(&M::type_name(), "ros2msg", M::schema_text().as_bytes()).map_err(|e| self.err(e))?;
        let meta = BTreeMap::from([("offered_qos_profiles".to_string(), offered_qos(reliable, transient))]);
        let id = self.writer.add_channel(schema, topic, "cdr", &meta).map_err(|e| self.err(e))?;
        self.channels.insert(topic, id);
        Ok(())
    }

    fn write<M: RosMessage>(&mut self, topic: &'static str, m: &M, nanos: u64) -> Result<(), RecordError> {
        let channel_id = self.channels[topic];
        let header =
            mcap::records::MessageHeader { channel_id, sequence: self.sequence, log_time: nanos, publish_time: nanos };
        self.sequence += 1;
        self.writer.write_to_known_channel(&header, &to_cdr(m)).map_err(|e| self.err(e))
    }

    /// Writes one control step.
    pub fn write_step(&mut self, m: &SimMessages) -> Result<(), RecordError> {
        let t = m.stamp.as_nanos();
        self.write("/clock", &Clock { clock: m.stamp }, t)?;
        self.write("/scan", &m.scan, t)?;
        self.write("/odom", &m.odom, t)?;
        self.write("/tf", &m.tf, t)?;
        self.write("/cmd_vel", &m.cmd_vel, t)?;
        self.write("/goal_pose", &m.goal, t)
    }

    /// Writes the summary and index and closes the file.
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.writer.finish().map_err(|e| self.err(e))?;
        Ok(())
    }
}

/// Runs the environment's current episode to its end under `c`, tracing it and recording it
/// to `file`.
pub fn recorded_episode(
    env: &mut NavEnv,
    c: &mut dyn Controller,
    file: &Path,
) -> Result<(EpisodeStats, EpisodeTrace), RecordError> {
    let period = env.setup().task.control_period as f64;
    let frames = Frames::default();
    let mut rec = McapRecorder::create(file)?;
    let mut trace = EpisodeTrace::default();
    let mut failed = None;
    let stats = env.run_to_end(c, |e| {
        let t = trace.time.len() as f64 * period;
        trace.push(e, t as f32);
        if failed.is_none() {
            failed = rec.write_step(&SimMessages::of(e, t, &frames)).err();
        }
    });
    if let Some(e) = failed {
        return Err(e);
    }
    rec.finish()?;
    Ok((stats, trace))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rlnav_sim::GreedyGoal;
    use std::sync::Arc;

    #[test]
    fn recording_reads_back_with_schemas_and_one_message_per_topic_per_step() {
        let dir = std::env::temp_dir().join(format!("rlnav-mcap-{}", std::process::id()));
        let file = dir.join("ep.mcap");
        let setup = Arc::new(rlnav_sim::task::EnvSetup::from_scenario_name("empty-room").unwrap());
        let mut env = NavEnv::new(setup, 5).unwrap();
        let (stats, trace) = recorded_episode(&mut env, &mut GreedyGoal::default(), &file).unwrap();
        let bytes = std::fs::read(&file).unwrap();
        let steps = trace.time.len();
        assert_eq!(steps as u32, stats.length + 1);
        let mut per_topic: BTreeMap<String, usize> = BTreeMap::new();
        let mut last_scan = None;
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            assert_eq!(m.channel.message_encoding, "cdr");
            let schema = m.channel.schema.as_ref().unwrap();
            assert_eq!(schema.encoding, "ros2msg");
            *per_topic.entry(m.channel.topic.clone()).or_default() += 1;
            if m.channel.topic == "/scan" {
                assert_eq!(schema.name, "sensor_msgs/msg/LaserScan");
                last_scan = Some(msg::from_cdr::<msg::LaserScan>(&m.data).unwrap());
            }
        }
        for topic in ["/scan", "/odom", "/tf", "/cmd_vel", "/goal_pose", "/clock"] {
            assert_eq!(per_topic.get(topic), Some(&steps), "{topic}");
        }
        assert_eq!(last_scan.unwrap().ranges, env.ranges());
        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary section");
        assert!(!summary.chunk_indexes.is_empty());
        assert!(summary.chunk_indexes.iter().all(|c| c.compression == "zstd"), "zstd chunks");
        let raw: u64 = summary.chunk_indexes.iter().map(|c| c.uncompressed_size).sum();
        let packed: u64 = summary.chunk_indexes.iter().map(|c| c.compressed_size).sum();
        assert!(packed * 2 < raw, "compressed {packed} of {raw} bytes");
        std::fs::remove_dir_all(dir).ok();
    }
}
