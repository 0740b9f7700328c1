//! Which robot a run drives, as written on the command line: `sim`, `virtual-ur` or
//! `ur://HOST[:PORT]`.

use std::fmt;
use std::str::FromStr;

/// Which robot a run drives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RobotTarget {
    /// The in-process simulated cell.
    Sim,
    /// The simulated cell behind an in-process virtual UR controller on loopback, driven over
    /// RTDE by the production client.
    VirtualUr,
    /// A real UR controller.
    Ur {
        /// Host name or address.
        host: String,
        /// RTDE port.
        port: u16,
    },
}

impl FromStr for RobotTarget {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        const EXPECTED: &str = "expected sim, virtual-ur or ur://HOST[:PORT]";
        match s {
            "sim" => return Ok(Self::Sim),
            "virtual-ur" => return Ok(Self::VirtualUr),
            _ => {}
        }
        let Some(rest) = s.strip_prefix("ur://") else {
            return Err(format!("unknown robot {s:?}: {EXPECTED}"));
        };
        let bad = |why: &str| format!("robot {s:?}: {why} ({EXPECTED}, e.g. ur://192.168.0.10)");
        let (host, port) = if let Some(v6) = rest.strip_prefix('[') {
            let (addr, after) = v6.split_once(']').ok_or_else(|| bad("unclosed '['"))?;
            addr.parse::<std::net::Ipv6Addr>()
                .map_err(|_| bad("not an IPv6 address in brackets"))?;
            let port = match after {
                "" => None,
                p => Some(p.strip_prefix(':').ok_or_else(|| bad("junk after ']'"))?),
            };
            (addr, port)
        } else {
            match rest.split_once(':') {
                Some((h, p)) => (h, Some(p)),
                None => (rest, None),
            }
        };
        if host.is_empty() {
            return Err(bad("no host"));
        }
        let host_ok = host.contains(':')
            || host
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '.' || c == '-');
        if !host_ok || host.starts_with(['.', '-']) {
            return Err(bad("the host may hold only letters, digits, '.' and '-'"));
        }
        let port = match port {
            None => robots::rtde::RTDE_PORT,
            Some(p) => match p.parse::<u16>() {
                Ok(p) if p > 0 => p,
                _ => return Err(bad("the port must be a number from 1 to 65535")),
            },
        };
        Ok(Self::Ur {
            host: host.to_string(),
            port,
        })
    }
}

impl fmt::Display for RobotTarget {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Sim => f.write_str("sim"),
            Self::VirtualUr => f.write_str("virtual-ur"),
            Self::Ur { host, port } if host.contains(':') => write!(f, "ur://[{host}]:{port}"),
            Self::Ur { host, port } => write!(f, "ur://{host}:{port}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_displays_every_form() {
        for (text, shown) in [
            ("sim", "sim"),
            ("virtual-ur", "virtual-ur"),
            ("ur://10.0.0.2", "ur://10.0.0.2:30004"),
            ("ur://cell-7.local:30005", "ur://cell-7.local:30005"),
            ("ur://[::1]:30004", "ur://[::1]:30004"),
        ] {
            let t: RobotTarget = text.parse().unwrap();
            assert_eq!(t.to_string(), shown);
            assert_eq!(shown.parse::<RobotTarget>().unwrap(), t);
        }
    }

    #[test]
    fn rejects_what_is_not_a_robot_with_the_reason() {
        for (text, why) in [
            ("ur5", "unknown robot"),
            ("ur://", "no host"),
            ("ur://host:0", "port must be a number"),
            ("ur://host:99999", "port must be a number"),
            ("ur://bad host", "only letters"),
            ("ur://[::1", "unclosed"),
        ] {
            let e = text.parse::<RobotTarget>().unwrap_err();
            assert!(e.contains(why), "{text}: {e}");
        }
    }
}
