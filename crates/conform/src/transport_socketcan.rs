//! The device under test on a SocketCAN interface of this host (cargo feature `socketcan`,
//! Linux): a `CAN_RAW` socket on `can0`, `vcan0`, … on the wall clock, frames stamped by the
//! kernel.
//!
//! Before opening the socket the interface is looked up in sysfs, so that a wrong name, an
//! interface that is not CAN (`eth0`) or one that is down is reported as such, rather than
//! as the socket's bare `ENODEV` or `ENETDOWN`.

use std::path::Path;

use cantwin_gateway::socketcan::SocketCan;
use cantwin_gateway::{BusConnector, BusPort, PortError};

use crate::PortTransport;

/// The link type of CAN interfaces (`ARPHRD_CAN`, linux/if_arp.h), as
/// `/sys/class/net/<name>/type` shows it.
const ARPHRD_CAN: u32 = 280;
/// `IFF_UP` (linux/if.h) in `/sys/class/net/<name>/flags`.
const IFF_UP: u32 = 0x1;
/// The longest interface name (`IFNAMSIZ` 16, with its terminating NUL).
const MAX_NAME: usize = 15;

/// Why a SocketCAN interface could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum SocketCanError {
    /// Not a name an interface can have.
    #[error("{0:?} is not an interface name (1 to 15 bytes, no '/' or white space)")]
    BadName(String),
    /// No interface of that name.
    #[error("no network interface named {0:?} (ip link add dev {0} type vcan, for a virtual one)")]
    NoInterface(String),
    /// The interface exists and is not a CAN interface.
    #[error("{name:?} is not a CAN interface (link type {link_type}; CAN is {ARPHRD_CAN})")]
    NotCan {
        /// The interface.
        name: String,
        /// Its link type.
        link_type: u32,
    },
    /// The interface is down.
    #[error("CAN interface {0:?} is down (ip link set {0} up)")]
    Down(String),
    /// sysfs could not be read, or the socket could not be opened.
    #[error("SocketCAN interface {name:?}: {why}")]
    Open {
        /// The interface.
        name: String,
        /// What failed.
        why: String,
    },
}

fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= MAX_NAME
        && name != "."
        && name != ".."
        && !name.contains('/')
        && !name.chars().any(char::is_whitespace)
}

fn read_number(path: &Path) -> Option<u32> {
    let text = std::fs::read_to_string(path).ok()?;
    let text = text.trim();
    match text.strip_prefix("0x") {
        Some(hex) => u32::from_str_radix(hex, 16).ok(),
        None => text.parse().ok(),
    }
}

/// Checks `name` in the sysfs network class directory `class` (`/sys/class/net`).
fn check_interface(class: &Path, name: &str) -> Result<(), SocketCanError> {
    if !valid_name(name) {
        return Err(SocketCanError::BadName(name.to_owned()));
    }
    let dir = class.join(name);
    if !dir.exists() {
        return Err(SocketCanError::NoInterface(name.to_owned()));
    }
    let unreadable = |what: &str| SocketCanError::Open {
        name: name.to_owned(),
        why: format!("cannot read {}", dir.join(what).display()),
    };
    let link_type = read_number(&dir.join("type")).ok_or_else(|| unreadable("type"))?;
    if link_type != ARPHRD_CAN {
        return Err(SocketCanError::NotCan {
            name: name.to_owned(),
            link_type,
        });
    }
    let flags = read_number(&dir.join("flags")).ok_or_else(|| unreadable("flags"))?;
    if flags & IFF_UP == 0 {
        return Err(SocketCanError::Down(name.to_owned()));
    }
    Ok(())
}

/// Open the CAN interface `name` as the runner's transport.
pub fn open(name: &str) -> Result<PortTransport<Box<dyn BusPort>>, SocketCanError> {
    check_interface(Path::new("/sys/class/net"), name)?;
    // The receive buffer is the socket's own; the capacity asked for is not used.
    let port = SocketCan.open(name, 0).map_err(|e| match e {
        PortError::UnknownChannel(_) => SocketCanError::NoInterface(name.to_owned()),
        e => SocketCanError::Open {
            name: name.to_owned(),
            why: e.to_string(),
        },
    })?;
    Ok(PortTransport::new(port, format!("SocketCAN {name}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sysfs network class directory with one interface.
    fn class_with(name: &str, link_type: &str, flags: &str) -> std::path::PathBuf {
        let class = std::env::temp_dir().join(format!(
            "cantwin-conform-sysfs-{}-{name}-{flags}",
            std::process::id()
        ));
        let dir = class.join(name);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("type"), format!("{link_type}\n")).unwrap();
        std::fs::write(dir.join("flags"), format!("{flags}\n")).unwrap();
        class
    }

    #[test]
    fn an_up_can_interface_passes_and_a_down_one_is_named() {
        let up = class_with("vcan0", "280", "0x1");
        assert!(check_interface(&up, "vcan0").is_ok());
        let down = class_with("vcan0", "280", "0x1002");
        match check_interface(&down, "vcan0") {
            Err(e @ SocketCanError::Down(_)) => {
                assert!(e.to_string().contains("ip link set vcan0 up"), "{e}")
            }
            other => panic!("{other:?}"),
        }
        for dir in [up, down] {
            std::fs::remove_dir_all(dir).unwrap();
        }
    }

    #[test]
    fn an_ethernet_interface_is_not_can() {
        let class = class_with("eth0", "1", "0x1003");
        assert!(matches!(
            check_interface(&class, "eth0"),
            Err(SocketCanError::NotCan { link_type: 1, .. })
        ));
        std::fs::remove_dir_all(class).unwrap();
    }

    #[test]
    fn names_that_cannot_be_interfaces_are_refused_before_any_lookup() {
        for bad in ["", ".", "..", "../../etc", "can 0", "sixteen-chars-00"] {
            assert!(
                matches!(open(bad), Err(SocketCanError::BadName(_))),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn the_hosts_own_interfaces_are_looked_up() {
        // Every Linux host has the loopback interface, link type 772 (ARPHRD_LOOPBACK).
        assert!(matches!(
            open("lo"),
            Err(SocketCanError::NotCan { link_type: 772, .. })
        ));
        assert!(matches!(
            open("cantwinnone0"),
            Err(SocketCanError::NoInterface(_))
        ));
    }
}
