//! One explicit request over a connection opened for it and closed after it: which
//! connection a request needs, and what the scanner's events say about its answer.
//!
//! A request goes over the Predefined Master/Slave Connection Set (Allocate with the
//! explicit choice, then Release) when class and instance fit the 8/8 body format the
//! slave grants on it; a wider class or instance (the ADV200 card's Parameter object with
//! instance = PAR above 255, EXP-CAN/DN-ADV manual §3.4.2 note 1) opens a UCMM connection
//! asking for 8/16 or 16/16 and closes it afterwards.

use super::{Scanner, ScannerError, ScannerEvent};
use crate::wire::{BodyFormat, MacId, choice};

/// The connection a one-off request goes over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Connection {
    /// The explicit connection of the Predefined Master/Slave Connection Set.
    Predefined,
    /// A UCMM connection asking for this body format.
    Ucmm(BodyFormat),
}

impl Connection {
    /// The connection a request to `class`/`instance` needs: UCMM with 16/16 for a class
    /// above 255, with 8/16 for an instance above 255, else the predefined set.
    pub fn for_path(class: u16, instance: u16) -> Connection {
        if class > 0xFF {
            Connection::Ucmm(BodyFormat::F16_16)
        } else if instance > 0xFF {
            Connection::Ucmm(BodyFormat::F8_16)
        } else {
            Connection::Predefined
        }
    }

    /// What getting the connection is called in messages: "opening a UCMM connection" or
    /// "allocating the explicit connection".
    pub fn opening(self) -> &'static str {
        match self {
            Connection::Ucmm(_) => "opening a UCMM connection",
            Connection::Predefined => "allocating the explicit connection",
        }
    }
}

/// What the events of a one-off request say about its answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// The request's success response.
    Reply(Vec<u8>),
    /// An error response, to the request or to opening the connection (the first one).
    Error {
        /// The service answered: the request's, or the connection's (Allocate, open …).
        service: u8,
        /// General status.
        general: u8,
        /// Additional code.
        additional: u8,
    },
    /// The request got no answer.
    RequestTimeout,
    /// Getting or giving back the connection got no answer.
    ConnectionTimeout,
    /// No event said anything about the request.
    NoAnswer,
}

impl Scanner {
    /// Queues one request to `slave` over a connection opened for it and closed after it
    /// (three operations, each reporting one event); returns the connection chosen.
    pub fn one_off_request(
        &mut self,
        slave: MacId,
        service: u8,
        class: u16,
        instance: u16,
        data: &[u8],
    ) -> Result<Connection, ScannerError> {
        let connection = Connection::for_path(class, instance);
        match connection {
            Connection::Ucmm(format) => self.open_ucmm(slave, format)?,
            Connection::Predefined => self.allocate(slave, choice::EXPLICIT)?,
        }
        self.request(slave, service, class, instance, data)?;
        match connection {
            Connection::Ucmm(_) => self.close_ucmm(slave)?,
            Connection::Predefined => self.release(slave, choice::EXPLICIT)?,
        }
        Ok(connection)
    }
}

/// The answer to a one-off request for `service`, from the events it reported: a success
/// response wins; otherwise the first error response or timeout.
pub fn outcome(events: impl IntoIterator<Item = ScannerEvent>, service: u8) -> Outcome {
    let mut reply = None;
    for ev in events {
        match ev {
            ScannerEvent::Response { data, .. } => reply = Some(Outcome::Reply(data)),
            ScannerEvent::Error {
                service: svc,
                general,
                additional,
                ..
            } => {
                reply.get_or_insert(Outcome::Error {
                    service: svc,
                    general,
                    additional,
                });
            }
            ScannerEvent::Timeout { service: svc, .. } if svc == service => {
                reply.get_or_insert(Outcome::RequestTimeout);
            }
            ScannerEvent::Timeout { .. } => {
                reply.get_or_insert(Outcome::ConnectionTimeout);
            }
            _ => {}
        }
    }
    reply.unwrap_or(Outcome::NoAnswer)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::service;

    #[test]
    fn wide_paths_need_a_ucmm_connection() {
        assert_eq!(Connection::for_path(1, 1), Connection::Predefined);
        assert_eq!(
            Connection::for_path(0x0F, 600),
            Connection::Ucmm(BodyFormat::F8_16)
        );
        assert_eq!(
            Connection::for_path(0x300, 1),
            Connection::Ucmm(BodyFormat::F16_16)
        );
    }

    #[test]
    fn a_response_wins_over_errors_and_the_first_error_is_kept() {
        let slave = MacId::new(12).unwrap();
        let get = service::GET_ATTRIBUTE_SINGLE;
        let err = |general| ScannerEvent::Error {
            slave,
            service: get,
            general,
            additional: 0xFF,
        };
        assert_eq!(
            outcome([err(0x14), err(0x16)], get),
            Outcome::Error {
                service: get,
                general: 0x14,
                additional: 0xFF
            }
        );
        let ok = ScannerEvent::Response {
            slave,
            service: get,
            data: vec![1],
        };
        assert_eq!(outcome([err(0x14), ok], get), Outcome::Reply(vec![1]));
        assert_eq!(outcome([], get), Outcome::NoAnswer);
    }
}
