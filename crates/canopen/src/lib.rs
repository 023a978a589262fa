//! A sans-IO CANopen device stack (CiA 301).
//!
//! * [`od`]: the object dictionary — shared descriptions, per-device values, device hooks
//!   and the [`ObjectAccess`] view the SDO server works through;
//! * [`abort`]: SDO abort codes ([`AbortCode`]);
//! * [`sdo`]: SDO frames and the SDO server ([`sdo::SdoServer`]).
//!
//! ```
//! use std::sync::Arc;
//! use cantwin_canopen::{AbortCode, ObjectAccess};
//! use cantwin_canopen::od::{Access, DataType, ObjectDictionary, OdBuilder, SubObject, Value};
//!
//! let desc = OdBuilder::new()
//!     .var(0x1017, SubObject::new("Producer heartbeat time", DataType::Unsigned16, Access::Rw))
//!     .var(0x1018, SubObject::new("Vendor", DataType::Unsigned32, Access::Const))
//!     .build()
//!     .expect("a valid dictionary");
//! let mut od = ObjectDictionary::new(Arc::new(desc), 5);
//! od.write(0x1017, 0, &[0xE8, 0x03])?;
//! assert_eq!(od.get(0x1017, 0)?, Value::Unsigned16(1000));
//! assert_eq!(od.write(0x1018, 0, &[0; 4]), Err(AbortCode::READ_ONLY));
//! # Ok::<(), AbortCode>(())
//! ```
#![forbid(unsafe_code)]

pub mod abort;
pub mod bench;
pub mod cob_id;
pub mod device;
pub mod emcy;
pub mod error_behaviour;
#[doc(hidden)]
pub mod fuzz;
pub mod guarding;
pub mod heartbeat;
pub mod lss;
pub mod master;
pub mod nmt;
pub mod objects;
pub mod od;
pub mod pdo;
pub mod sdo;
pub mod storage;
pub mod sync;
pub mod time;
pub mod wire;

pub use abort::AbortCode;
pub use od::ObjectAccess;
