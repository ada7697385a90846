//! The thin layer over ros2-client/RustDDS the node and the bridge use: a participant (bound
//! to loopback when asked), one ROS 2 node on it, typed publishers and subscriptions with the
//! QoS ROS uses for each kind of topic (ros2-client's defaults are not ROS's), and the node's
//! background spinner (graph and discovery information, so `ros2 node list` sees it).

use crate::msg::RosMessage;
use ros2_client::dds::{Context, Node, Publisher, Subscription};
use ros2_client::qos::{Durability, History, WhenFull};
use ros2_client::{MessageTypeName, Name, NodeName, NodeOptions, QosProfile};
use std::net::{IpAddr, Ipv4Addr};

/// Errors setting up DDS.
#[derive(Debug, thiserror::Error)]
pub enum BusError {
    /// The participant, node, topic or endpoint could not be created.
    #[error("ROS 2 {what}: {message}")]
    Create {
        /// What was being created.
        what: String,
        /// Why it failed.
        message: String,
    },
}

fn create(what: impl Into<String>) -> impl FnOnce(String) -> BusError {
    let what = what.into();
    move |message| BusError::Create { what, message }
}

/// The QoS profiles ROS 2 uses; in parameter files `sensor_data`, `reliable` (or `default`)
/// and `transient_local` (or `latched`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Qos {
    /// `rmw_qos_profile_sensor_data`: best effort, keep last 5, volatile (`/scan`).
    SensorData,
    /// `rmw_qos_profile_default`: reliable, keep last 10, volatile (commands, odometry).
    #[serde(rename = "reliable", alias = "default")]
    Default,
    /// Reliable, keep last 1, transient local (`/tf_static`, latched topics).
    #[serde(rename = "transient_local", alias = "latched")]
    Latched,
}

impl Qos {
    /// The profile, set in full: ros2-client's defaults differ from ROS's.
    pub fn profile(self) -> QosProfile {
        let base = QosProfile::subscription_default();
        match self {
            Qos::SensorData => {
                base.reliability_best_effort().history(History::KeepLast { depth: 5 }).durability(Durability::Volatile)
            }
            Qos::Default => base
                .reliability_reliable(WhenFull::DEFAULT)
                .history(History::KeepLast { depth: 10 })
                .durability(Durability::Volatile),
            Qos::Latched => base
                .reliability_reliable(WhenFull::DEFAULT)
                .history(History::KeepLast { depth: 1 })
                .durability(Durability::TransientLocal),
        }
    }
}

/// Where DDS may talk.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Reach {
    /// Every interface (ROS's default).
    #[default]
    Network,
    /// Loopback only (`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, tests).
    Localhost,
}

impl Reach {
    /// `Localhost` when the environment asks for it as ROS 2 does
    /// (`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` or the older `ROS_LOCALHOST_ONLY=1`).
    pub fn from_env() -> Self {
        let range = std::env::var("ROS_AUTOMATIC_DISCOVERY_RANGE").unwrap_or_default();
        let old = std::env::var("ROS_LOCALHOST_ONLY").unwrap_or_default();
        if range.eq_ignore_ascii_case("LOCALHOST") || old == "1" { Reach::Localhost } else { Reach::Network }
    }
}

/// The DDS domain id: `ROS_DOMAIN_ID` as ROS 2 reads it, else 0.
pub fn domain_from_env() -> Result<u16, BusError> {
    match std::env::var("ROS_DOMAIN_ID") {
        Ok(s) if !s.trim().is_empty() => {
            s.trim().parse::<u16>().ok().filter(|d| *d <= 232).ok_or_else(|| BusError::Create {
                what: "domain".into(),
                message: format!("ROS_DOMAIN_ID `{s}` is not a domain id (0-232)"),
            })
        }
        _ => Ok(0),
    }
}

/// One ROS 2 node on its own DDS participant.
pub struct Bus {
    node: Node,
    _spinner: std::thread::JoinHandle<()>,
}

impl Bus {
    /// Joins `domain` as node `name` (e.g. `rlnav_policy`) in the root namespace, restricted as
    /// `reach` says.
    pub fn new(name: &str, domain: u16, reach: Reach) -> Result<Self, BusError> {
        Self::in_namespace("/", name, domain, reach)
    }

    /// Like [`Bus::new`], for a node in `namespace` (`/robot1`; empty or `/`: the root).
    pub fn in_namespace(namespace: &str, name: &str, domain: u16, reach: Reach) -> Result<Self, BusError> {
        let namespace = if namespace.is_empty() { "/" } else { namespace };
        let mut b = rustdds::DomainParticipantBuilder::new(domain);
        if reach == Reach::Localhost {
            b = b.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]);
        }
        let participant = b.build().map_err(|e| create("participant")(e.to_string()))?;
        let context = Context::from_domain_participant(participant).map_err(|e| create("context")(e.to_string()))?;
        let node_name = NodeName::new(namespace, name)
            .map_err(|e| create(format!("node name `{namespace}/{name}`"))(format!("{e:?}")))?;
        let mut node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(true))
            .map_err(|e| create("node")(format!("{e:?}")))?;
        let spinner = node.spinner().map_err(|e| create("spinner")(format!("{e:?}")))?;
        let handle = std::thread::Builder::new()
            .name(format!("{name}-spinner"))
            .spawn(move || {
                // Ends when the node is dropped.
                let _ = futures::executor::block_on(spinner.spin());
            })
            .map_err(|e| create("spinner thread")(e.to_string()))?;
        Ok(Self { node, _spinner: handle })
    }

    fn topic<M: RosMessage>(&mut self, topic: &str, qos: Qos) -> Result<rustdds::Topic, BusError> {
        let name = Name::parse(topic).map_err(|e| create(format!("topic name `{topic}`"))(format!("{e:?}")))?;
        self.node
            .create_topic(&name, MessageTypeName::new(M::PACKAGE, M::NAME), &qos.profile())
            .map_err(|e| create(format!("topic `{topic}`"))(format!("{e:?}")))
    }

    /// A publisher of `M` on `topic`.
    pub fn publisher<M: RosMessage>(&mut self, topic: &str, qos: Qos) -> Result<Publisher<M>, BusError> {
        let t = self.topic::<M>(topic, qos)?;
        self.node
            .create_publisher::<M>(&t, Some(qos.profile()))
            .map_err(|e| create(format!("publisher on `{topic}`"))(format!("{e:?}")))
    }

    /// A subscription to `M` on `topic`.
    pub fn subscription<M: RosMessage>(&mut self, topic: &str, qos: Qos) -> Result<Subscription<M>, BusError> {
        let t = self.topic::<M>(topic, qos)?;
        self.node
            .create_subscription::<M>(&t, Some(qos.profile()))
            .map_err(|e| create(format!("subscription to `{topic}`"))(format!("{e:?}")))
    }

    /// An action server for `action` (`follow_path`, resolved like a topic) of type
    /// `package/action/name`, with the QoS ROS 2's actions use: reliable volatile services and
    /// feedback, and a transient-local status topic (rcl's defaults; a client asks for those).
    pub fn action_server<G, R, F>(
        &mut self,
        action: &str,
        package: &str,
        name: &str,
    ) -> Result<ros2_client::action::ActionServer<G, R, F>, BusError>
    where
        G: ros2_client::Message + Clone + 'static,
        R: ros2_client::Message + Clone + 'static,
        F: ros2_client::Message + 'static,
    {
        let n = Name::parse(action).map_err(|e| create(format!("action name `{action}`"))(format!("{e:?}")))?;
        let qos = ros2_client::action::ActionServerQosPolicies {
            goal_service: Qos::Default.profile(),
            result_service: Qos::Default.profile(),
            cancel_service: Qos::Default.profile(),
            feedback_publisher: Qos::Default.profile(),
            status_publisher: Qos::Latched.profile(),
        };
        self.node
            .create_action_server::<G, R, F>(
                ros2_client::dds::ServiceMapping::Enhanced,
                &n,
                &ros2_client::ActionTypeName::new(package, name),
                qos,
            )
            .map_err(|e| create(format!("action server `{action}`"))(format!("{e:?}")))
    }

    /// An action client for `action`, as [`Bus::action_server`] serves it (tests, tools).
    pub fn action_client<G, R, F>(
        &mut self,
        action: &str,
        package: &str,
        name: &str,
    ) -> Result<ros2_client::action::ActionClient<G, R, F>, BusError>
    where
        G: ros2_client::Message + Clone + 'static,
        R: ros2_client::Message + Clone + 'static,
        F: ros2_client::Message + 'static,
    {
        let n = Name::parse(action).map_err(|e| create(format!("action name `{action}`"))(format!("{e:?}")))?;
        let qos = ros2_client::action::ActionClientQosPolicies {
            goal_service: Qos::Default.profile(),
            result_service: Qos::Default.profile(),
            cancel_service: Qos::Default.profile(),
            feedback_subscription: Qos::Default.profile(),
            status_subscription: Qos::Latched.profile(),
        };
        self.node
            .create_action_client::<G, R, F>(
                ros2_client::dds::ServiceMapping::Enhanced,
                &n,
                &ros2_client::ActionTypeName::new(package, name),
                qos,
            )
            .map_err(|e| create(format!("action client `{action}`"))(format!("{e:?}")))
    }

    /// The underlying node (for the graph and logging).
    pub fn node(&self) -> &Node {
        &self.node
    }
}

/// Everything waiting on `sub`, oldest first; messages that do not decode are counted in
/// `dropped` instead (the network is never trusted to send well-formed data).
pub fn drain<M: RosMessage>(sub: &Subscription<M>, dropped: &mut u64) -> Vec<M> {
    let mut out = Vec::new();
    // Bounded, so that a flood cannot keep the loop from ticking.
    for _ in 0..1000 {
        match sub.take() {
            Ok(Some((m, _))) => out.push(m),
            Ok(None) => break,
            Err(_) => *dropped += 1,
        }
    }
    out
}
