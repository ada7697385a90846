//! The ROS 2 command-line arguments a node takes after `--ros-args` (as `ros2 run` and launch
//! files pass them): remapping (`-r FROM:=TO`, `__ns` and `__node`), parameters
//! (`-p NAME:=VALUE`, `--params-file FILE`) and `--log-level`.

use rlnav_sim::config::ConfigError;
use std::path::PathBuf;

/// What `--ros-args ... [--]` said.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RosArgs {
    /// `-r __node:=NAME`.
    pub node_name: Option<String>,
    /// `-r __ns:=/NAMESPACE`.
    pub namespace: Option<String>,
    /// `-r FROM:=TO` for topics, in order.
    pub remaps: Vec<(String, String)>,
    /// `-p NAME:=VALUE` (the value as YAML), in order.
    pub params: Vec<(String, String)>,
    /// `--params-file FILE`, in order.
    pub params_files: Vec<PathBuf>,
    /// `--log-level LEVEL` (`debug`, `info`, `warn`, `error`, `fatal`), or `NAME:=LEVEL` for
    /// one logger.
    pub log_level: Option<String>,
}

fn bad(message: String) -> ConfigError {
    ConfigError::Parse { file: "--ros-args".into(), message }
}

/// Splits `NAME:=VALUE`.
fn assignment(flag: &str, arg: Option<&String>) -> Result<(String, String), ConfigError> {
    let arg = arg.ok_or_else(|| bad(format!("{flag} needs NAME:=VALUE")))?;
    let (name, value) = arg.split_once(":=").ok_or_else(|| bad(format!("{flag} `{arg}`: expected NAME:=VALUE")))?;
    if name.is_empty() {
        return Err(bad(format!("{flag} `{arg}`: empty name")));
    }
    Ok((name.to_string(), value.to_string()))
}

impl RosArgs {
    /// Parses the arguments that followed `--ros-args` (up to a `--`, which ends them).
    pub fn parse(args: &[String]) -> Result<Self, ConfigError> {
        let mut a = RosArgs::default();
        let mut it = args.iter();
        while let Some(flag) = it.next() {
            match flag.as_str() {
                "--" => break,
                "--ros-args" => {}
                "-r" | "--remap" => {
                    let (from, to) = assignment(flag, it.next())?;
                    match from.as_str() {
                        "__ns" => {
                            if !to.starts_with('/') || !valid_name(&to) {
                                return Err(bad(format!("__ns:=`{to}`: expected an absolute namespace like /robot1")));
                            }
                            a.namespace = Some(to.trim_end_matches('/').to_string());
                        }
                        "__node" | "__name" => {
                            if to.is_empty() || !to.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                                return Err(bad(format!("{from}:=`{to}`: expected a node name (letters, digits, _)")));
                            }
                            a.node_name = Some(to);
                        }
                        _ => {
                            for n in [&from, &to] {
                                if !valid_name(n) {
                                    return Err(bad(format!("-r {from}:={to}: `{n}` is not a topic name")));
                                }
                            }
                            a.remaps.push((from, to));
                        }
                    }
                }
                "-p" | "--param" => a.params.push(assignment(flag, it.next())?),
                "--params-file" => {
                    let f = it.next().ok_or_else(|| bad("--params-file needs a file".into()))?;
                    a.params_files.push(PathBuf::from(f));
                }
                "--log-level" => {
                    let l = it.next().ok_or_else(|| bad("--log-level needs a level".into()))?;
                    a.log_level = Some(l.clone());
                }
                "-e"
                | "--enclave"
                | "--disable-rosout-logs"
                | "--disable-stdout-logs"
                | "--enable-rosout-logs"
                | "--enable-stdout-logs"
                | "--disable-external-lib-logs" => {
                    return Err(bad(format!("`{flag}` is not supported by rlnav")));
                }
                other => {
                    return Err(bad(format!(
                        "unknown argument `{other}` (expected -r, -p, --params-file, --log-level)"
                    )));
                }
            }
        }
        Ok(a)
    }

    /// The `RUST_LOG`-style filter for `--log-level` (ROS's `fatal` is `error`), if given.
    pub fn log_filter(&self) -> Option<String> {
        let level = |l: &str| match l.to_ascii_lowercase().as_str() {
            "fatal" => "error".to_string(),
            other => other.to_string(),
        };
        self.log_level.as_ref().map(|l| match l.split_once(":=") {
            Some((name, l)) => format!("warn,{name}={}", level(l)),
            None => level(l),
        })
    }
}

/// Whether `name` can be a ROS topic name (absolute, relative or private): letters, digits,
/// `_` and `/` separators, an optional leading `~`; no empty token, not ending in `/`.
pub fn valid_name(name: &str) -> bool {
    let body = name.strip_prefix('~').unwrap_or(name);
    let body = body.strip_prefix('/').unwrap_or(body);
    !body.is_empty()
        && body.split('/').all(|t| {
            !t.is_empty()
                && t.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !t.starts_with(|c: char| c.is_ascii_digit())
        })
}

/// The absolute name of topic `name` for a node `node` in `namespace` (`""` or `/` for the
/// root): absolute names stay, relative ones go under the namespace, private ones (`~/x`)
/// under the node.
pub fn resolve(namespace: &str, node: &str, name: &str) -> String {
    let ns = namespace.trim_end_matches('/');
    if name.starts_with('/') {
        name.to_string()
    } else if let Some(private) = name.strip_prefix('~') {
        format!("{ns}/{node}/{}", private.trim_start_matches('/'))
    } else {
        format!("{ns}/{name}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn ros_args_parse_as_ros_2_passes_them() {
        let a = RosArgs::parse(&args(
            "-r __ns:=/robot1 -r scan:=/front/scan --remap __node:=planner -p max_linear:=0.2 \
             --param goal:=[3.0,1.0] --params-file nav2.yaml --log-level debug -- ignored",
        ))
        .unwrap();
        assert_eq!(a.namespace.as_deref(), Some("/robot1"));
        assert_eq!(a.node_name.as_deref(), Some("planner"));
        assert_eq!(a.remaps, vec![("scan".to_string(), "/front/scan".to_string())]);
        assert_eq!(a.params, vec![("max_linear".into(), "0.2".into()), ("goal".into(), "[3.0,1.0]".into())]);
        assert_eq!(a.params_files, vec![PathBuf::from("nav2.yaml")]);
        assert_eq!(a.log_filter().as_deref(), Some("debug"));
        for (bad_args, says) in [
            ("-r scan", "NAME:=VALUE"),
            ("-p :=1", "empty name"),
            ("-r __ns:=robot1", "absolute namespace"),
            ("-r sc-an:=/x", "not a topic name"),
            ("--frobnicate", "unknown argument `--frobnicate`"),
            ("-e /enclave", "not supported"),
            ("--params-file", "needs a file"),
        ] {
            let e = RosArgs::parse(&args(bad_args)).unwrap_err().to_string();
            assert!(e.contains("--ros-args") && e.contains(says), "{bad_args}: {e}");
        }
    }

    #[test]
    fn names_resolve_as_ros_2_resolves_them() {
        assert_eq!(resolve("", "n", "scan"), "/scan");
        assert_eq!(resolve("/", "n", "scan"), "/scan");
        assert_eq!(resolve("/robot1", "n", "scan"), "/robot1/scan");
        assert_eq!(resolve("/robot1", "n", "/tf"), "/tf");
        assert_eq!(resolve("/robot1", "n", "~/status"), "/robot1/n/status");
        for ok in ["scan", "/scan", "robot1/scan", "~/status", "rlnav/status"] {
            assert!(valid_name(ok), "{ok}");
        }
        for bad in ["", "/", "scan/", "a//b", "sc an", "1scan", "/tf?"] {
            assert!(!valid_name(bad), "{bad}");
        }
    }
}
