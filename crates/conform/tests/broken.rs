//! The suite discriminates: against devices with one deliberate fault each (see
//! [`broken::Fault`]), the case written for that fault fails, while the same device without
//! the fault passes the same cases. Each run is in virtual time and limited to the area of
//! the case.
#![allow(clippy::unwrap_used)]

#[path = "broken/mod.rs"]
mod broken;

use std::sync::Arc;

use broken::{Fault, NODE_ID};
use cantwin_can::Duration;
use cantwin_conform::{Area, Options, Profile, Report, Verdict, VirtualBus, run};

/// The case each fault is meant to be caught by, and its area.
fn case_for(fault: Fault) -> (&'static str, Area) {
    match fault {
        Fault::SdoInStopped => ("nmt.sdo-stopped", Area::Nmt),
        Fault::ToggleIgnored => ("sdo.abort-toggle", Area::Sdo),
        Fault::NoBootUpAfterResetCommunication => ("nmt.boot-up-reset-communication", Area::Nmt),
        Fault::MappingChangeOnValidPdo => ("pdo.mapping-procedure", Area::Pdo),
        Fault::WrongBlockUploadCrc => ("sdo.block-upload", Area::Sdo),
        Fault::HeartbeatAtTwiceThePeriod => ("error-control.heartbeat-period", Area::ErrorControl),
        Fault::StoreWithoutSignature => ("store.wrong-signature", Area::StoreRestore),
        Fault::PdoCobIdChangeWhileValid => ("pdo.cob-id-change-valid", Area::Pdo),
        Fault::ErrorHistoryWriteAccepted => ("emcy.history", Area::SyncEmcyTime),
        Fault::BlockDownloadCrcNotChecked => ("sdo.abort-crc", Area::Sdo),
        Fault::TpdoInPreOperational => ("nmt.pdo-operational-only", Area::Nmt),
        Fault::DuplicateHeartbeatConsumerAccepted => (
            "error-control.heartbeat-consumer-duplicate",
            Area::ErrorControl,
        ),
        Fault::EmcyCobIdChangeWhileValid => ("emcy.cob-id-change-valid", Area::SyncEmcyTime),
        Fault::BlockUploadSwitchedOnPst0 => ("sdo.block-upload", Area::Sdo),
        Fault::AcyclicTpdoNeverSent => ("pdo.transmission-acyclic", Area::Pdo),
        Fault::PdoCobIdChangeWhileValidUnanswered => ("pdo.cob-id-change-valid", Area::Pdo),
        Fault::ResetIgnoredInStopped => ("nmt.reset-from-operational-stopped", Area::Nmt),
        Fault::OperationalReportedAfterBootUp => ("nmt.pre-operational-after-boot-up", Area::Nmt),
        Fault::RpdoProcessedInStopped | Fault::SyncTpdoInStopped | Fault::EmcyInStopped => {
            ("nmt.services-stopped", Area::Nmt)
        }
        Fault::RpdoProcessedInPreOperational => ("nmt.services-pre-operational", Area::Nmt),
        Fault::CyclicTypeAtEverySync => ("pdo.transmission-cyclic", Area::Pdo),
        Fault::RtrSyncTypeSentOnSync => ("pdo.transmission-rtr-sync", Area::Pdo),
        Fault::ReservedTransmissionTypeAccepted => ("pdo.transmission-reserved", Area::Pdo),
        Fault::UploadToggleIgnored => ("sdo.abort-toggle-upload", Area::Sdo),
        Fault::BlockUploadBlockSizeIgnored => ("sdo.block-upload", Area::Sdo),
        Fault::BlockDownloadBlockSizeZero => ("sdo.block-download", Area::Sdo),
        Fault::BlockDownloadWithoutSizeRefused => ("sdo.block-download-no-size", Area::Sdo),
        Fault::WriteOnlyEntryRead => ("sdo.abort-write-only", Area::Sdo),
        Fault::LowLimitNotChecked => ("sdo.abort-value-low", Area::Sdo),
        Fault::MappingEntryWrittenWhileEnabled => ("pdo.mapping-entry-while-enabled", Area::Pdo),
        Fault::MappingLengthNotChecked => ("pdo.mapping-length", Area::Pdo),
        Fault::NotMappableObjectMapped => ("pdo.mapping-not-mappable", Area::Pdo),
        Fault::AbsentObjectMapped => ("pdo.mapping-no-object", Area::Pdo),
        Fault::OldMappingSent => ("pdo.mapping-carried", Area::Pdo),
        Fault::ErrorHistoryNotCounted => ("emcy.history-records", Area::SyncEmcyTime),
        Fault::TimeProducerBitIgnored => ("time.producer", Area::SyncEmcyTime),
        Fault::TimeConsumerBitIgnored => ("time.consumer", Area::SyncEmcyTime),
        Fault::RestoreCommunicationIgnored => (
            "restore.communication-after-reset-communication",
            Area::StoreRestore,
        ),
        Fault::ResetCommunicationResetsApplication => {
            ("restore.application-after-reset-node", Area::StoreRestore)
        }
        Fault::RpdoIgnoredInOperational => ("pdo.rpdo-processed", Area::Pdo),
        Fault::NmtForAnyNodeId => ("nmt.other-node", Area::Nmt),
        Fault::InhibitedEmcyDropped => ("emcy.inhibit", Area::SyncEmcyTime),
        Fault::ErrorRegisterReadsZero | Fault::NoErrorResetEmcy => {
            ("emcy.error-register", Area::SyncEmcyTime)
        }
    }
}

/// Runs the cases of `area` against the device, broken by `fault` or not.
fn conform(fault: Option<Fault>, area: Area) -> Report {
    conform_powered(fault, area, broken::POWERED_BEFORE)
}

/// As [`conform`], with the device powered `powered` before the runner attaches.
fn conform_powered(fault: Option<Fault>, area: Area, powered: Duration) -> Report {
    conform_profiled(fault, area, powered, "")
}

/// As [`conform_powered`], with the deviations and features of profile file `profile`.
fn conform_profiled(fault: Option<Fault>, area: Area, powered: Duration, profile: &str) -> Report {
    let desc = Arc::new(broken::description());
    let eds = broken::eds(&desc);
    let file = cantwin_conform::ProfileFile::parse(profile).unwrap();
    let (sim, bus, _) = broken::simulation_powered(&desc, fault, powered);
    let mut transport = VirtualBus::new(sim, bus).unwrap();
    let options = Options {
        only: vec![area],
        ..Options::default()
    };
    run(
        &mut transport,
        NODE_ID,
        &eds,
        &Profile::from_eds(&eds).with_file(&file, "test"),
        &options,
        &mut |_| {},
    )
}

fn show(r: &Report) -> String {
    cantwin_conform::output::summary(r)
}

/// Checks that `fault` is caught by its case and that the device without it passes that
/// case.
fn caught(fault: Fault) {
    let (id, area) = case_for(fault);
    let good = conform(None, area);
    let case = good
        .case(id)
        .unwrap_or_else(|| panic!("no case {id} in the report:\n{}", show(&good)));
    assert_eq!(
        case.verdict,
        Verdict::Pass,
        "the unbroken device fails {id}: {}\n{}",
        case.detail,
        show(&good)
    );
    let bad = conform(Some(fault), area);
    let case = bad.case(id).unwrap();
    assert_eq!(
        case.verdict,
        Verdict::Fail,
        "{fault:?} is not caught by {id}: {}\n{}",
        case.detail,
        show(&bad)
    );
    assert!(!bad.passed(), "{fault:?}: the run passes\n{}", show(&bad));
}

/// As [`caught`], and no other case of the area fails: the case is the only one that
/// catches the fault.
fn caught_only(fault: Fault) {
    caught(fault);
    let (id, area) = case_for(fault);
    let bad = conform(Some(fault), area);
    for c in &bad.cases {
        if c.id != id {
            assert_ne!(
                c.verdict,
                Verdict::Fail,
                "{fault:?} is caught by {} too: {}\n{}",
                c.id,
                c.detail,
                show(&bad)
            );
        }
    }
}

#[test]
fn unbroken_device_passes_every_mandatory_case_of_every_area() {
    for area in Area::ALL {
        let r = conform(None, area);
        assert!(r.passed(), "{area:?}:\n{}", show(&r));
    }
}

#[test]
fn cia301_7_3_2_2_5_sdo_answered_in_stopped_is_caught() {
    caught(Fault::SdoInStopped);
}

#[test]
fn cia301_7_2_4_3_4_unchecked_toggle_bit_is_caught() {
    caught(Fault::ToggleIgnored);
}

#[test]
fn cia301_7_2_8_3_2_1_no_boot_up_after_reset_communication_is_caught() {
    caught(Fault::NoBootUpAfterResetCommunication);
}

/// The runner attached before the device's power-up (as `cantwin conform --scenario`
/// does): the power-up boot-up is not the answer to the first reset communication, so the
/// device that sends none after it is still caught, and the unbroken one still passes.
#[test]
fn cia301_7_2_8_3_2_1_power_up_boot_up_is_not_taken_for_the_reset_answer() {
    let id = "nmt.boot-up-reset-communication";
    let good = conform_powered(None, Area::Nmt, Duration::ZERO);
    let case = good.case(id).unwrap();
    assert_eq!(
        case.verdict,
        Verdict::Pass,
        "{}\n{}",
        case.detail,
        show(&good)
    );
    assert!(good.passed(), "{}", show(&good));
    let bad = conform_powered(
        Some(Fault::NoBootUpAfterResetCommunication),
        Area::Nmt,
        Duration::ZERO,
    );
    let case = bad.case(id).unwrap();
    assert_eq!(
        case.verdict,
        Verdict::Fail,
        "{}\n{}",
        case.detail,
        show(&bad)
    );
}

#[test]
fn cia301_7_5_2_38_mapping_change_on_a_valid_pdo_is_caught() {
    caught(Fault::MappingChangeOnValidPdo);
}

#[test]
fn cia301_7_2_4_3_16_wrong_block_upload_crc_is_caught() {
    caught(Fault::WrongBlockUploadCrc);
}

#[test]
fn cia301_7_2_8_3_2_2_heartbeat_at_twice_the_period_is_caught() {
    caught(Fault::HeartbeatAtTwiceThePeriod);
}

#[test]
fn cia301_7_5_2_17_emcy_cob_id_change_while_valid_is_caught() {
    caught(Fault::EmcyCobIdChangeWhileValid);
}

#[test]
fn cia301_7_2_4_3_13_block_upload_switched_to_an_ordinary_upload_on_pst_0_is_caught() {
    caught(Fault::BlockUploadSwitchedOnPst0);
}

#[test]
fn cia301_7_5_2_13_store_without_signature_is_caught() {
    caught(Fault::StoreWithoutSignature);
}

#[test]
fn cia301_7_5_2_37_pdo_cob_id_change_while_valid_is_caught() {
    caught(Fault::PdoCobIdChangeWhileValid);
}

#[test]
fn cia301_7_5_2_4_error_history_write_of_1_accepted_is_caught() {
    caught(Fault::ErrorHistoryWriteAccepted);
}

#[test]
fn cia301_7_2_4_3_11_unchecked_block_download_crc_is_caught() {
    caught(Fault::BlockDownloadCrcNotChecked);
}

#[test]
fn cia301_7_5_2_19_duplicate_heartbeat_consumer_entry_accepted_is_caught() {
    caught(Fault::DuplicateHeartbeatConsumerAccepted);
}

#[test]
fn cia301_7_3_2_2_5_tpdo_in_pre_operational_is_caught() {
    caught(Fault::TpdoInPreOperational);
}

#[test]
fn cia301_7_2_2_2_2_acyclic_tpdo_never_sent_is_caught() {
    caught(Fault::AcyclicTpdoNeverSent);
}

#[test]
fn cia301_7_5_2_37_pdo_cob_id_change_while_valid_unanswered_is_caught() {
    caught(Fault::PdoCobIdChangeWhileValidUnanswered);
}

/// Every case named above is in the catalogue, in the area the run is limited to.
#[test]
fn cia301_7_3_2_2_1_reset_ignored_in_stopped_is_caught() {
    caught_only(Fault::ResetIgnoredInStopped);
}

#[test]
fn cia301_7_3_2_2_1_operational_reported_after_boot_up_is_caught() {
    caught_only(Fault::OperationalReportedAfterBootUp);
}

#[test]
fn cia301_7_3_2_2_5_rpdo_processed_in_stopped_is_caught() {
    caught_only(Fault::RpdoProcessedInStopped);
}

#[test]
fn cia301_7_3_2_2_5_sync_tpdo_in_stopped_is_caught() {
    caught_only(Fault::SyncTpdoInStopped);
}

#[test]
fn cia301_7_3_2_2_5_emcy_in_stopped_is_caught() {
    caught_only(Fault::EmcyInStopped);
}

#[test]
fn cia301_7_3_2_2_5_rpdo_processed_in_pre_operational_is_caught() {
    caught_only(Fault::RpdoProcessedInPreOperational);
}

#[test]
fn cia301_7_5_2_37_cyclic_type_sent_at_every_sync_is_caught() {
    caught_only(Fault::CyclicTypeAtEverySync);
}

#[test]
fn cia301_7_5_2_37_type_252_sent_on_sync_is_caught() {
    caught_only(Fault::RtrSyncTypeSentOnSync);
}

#[test]
fn cia301_7_5_2_37_reserved_transmission_type_accepted_is_caught() {
    caught_only(Fault::ReservedTransmissionTypeAccepted);
}

#[test]
fn cia301_7_2_4_3_7_unchecked_upload_toggle_bit_is_caught() {
    caught_only(Fault::UploadToggleIgnored);
}

#[test]
fn cia301_7_2_4_3_12_block_size_ignored_by_the_block_upload_server_is_caught() {
    caught_only(Fault::BlockUploadBlockSizeIgnored);
}

/// The block size 0 is caught by both block download cases, and by no case that gives it
/// no meaning (the aborts of a block download send one segment).
#[test]
fn cia301_7_2_4_3_9_block_size_0_in_the_block_download_initiate_answer_is_caught() {
    caught(Fault::BlockDownloadBlockSizeZero);
    let bad = conform(Some(Fault::BlockDownloadBlockSizeZero), Area::Sdo);
    let c = bad.case("sdo.block-download-no-size").unwrap();
    assert_eq!(c.verdict, Verdict::Fail, "{}", c.detail);
    assert!(c.detail.contains("blocks of 0 segments"), "{}", c.detail);
}

#[test]
fn cia301_7_2_4_3_9_block_download_without_size_refused_is_caught() {
    caught_only(Fault::BlockDownloadWithoutSizeRefused);
}

#[test]
fn cia301_7_2_4_3_17_write_only_entry_answering_a_read_is_caught() {
    caught_only(Fault::WriteOnlyEntryRead);
}

#[test]
fn cia301_7_2_4_3_17_value_below_the_low_limit_taken_is_caught() {
    caught_only(Fault::LowLimitNotChecked);
}

#[test]
fn cia301_7_5_2_38_mapping_entry_written_while_sub_0_is_not_0_is_caught() {
    caught_only(Fault::MappingEntryWrittenWhileEnabled);
}

#[test]
fn cia301_7_5_2_38_mapping_longer_than_64_bits_taken_is_caught() {
    caught_only(Fault::MappingLengthNotChecked);
}

#[test]
fn cia301_7_5_2_38_object_that_cannot_be_mapped_taken_is_caught() {
    caught_only(Fault::NotMappableObjectMapped);
}

#[test]
fn cia301_7_5_2_38_absent_object_mapped_is_caught() {
    caught_only(Fault::AbsentObjectMapped);
}

#[test]
fn cia301_7_5_2_38_tpdo_sent_with_its_old_mapping_is_caught() {
    caught_only(Fault::OldMappingSent);
}

#[test]
fn cia301_7_5_2_4_error_history_that_does_not_count_is_caught() {
    caught_only(Fault::ErrorHistoryNotCounted);
}

#[test]
fn cia301_7_5_2_15_time_producer_bit_not_taken_is_caught() {
    caught_only(Fault::TimeProducerBitIgnored);
}

#[test]
fn cia301_7_5_2_15_time_consumer_bit_not_taken_is_caught() {
    caught_only(Fault::TimeConsumerBitIgnored);
}

#[test]
fn cia301_7_5_2_14_restore_of_the_communication_parameters_ignored_is_caught() {
    caught_only(Fault::RestoreCommunicationIgnored);
}

#[test]
fn cia301_7_3_2_2_1_application_area_reset_by_reset_communication_is_caught() {
    caught_only(Fault::ResetCommunicationResetsApplication);
}

#[test]
fn cia301_7_3_2_2_5_rpdo_ignored_in_operational_is_caught() {
    caught(Fault::RpdoIgnoredInOperational);
}

#[test]
fn cia301_7_2_8_3_1_nmt_command_for_another_node_id_obeyed_is_caught() {
    caught(Fault::NmtForAnyNodeId);
}

#[test]
fn cia301_7_5_2_2_error_register_that_reads_0_during_an_error_is_caught() {
    caught(Fault::ErrorRegisterReadsZero);
}

#[test]
fn cia301_7_2_7_1_missing_error_reset_emcy_is_caught() {
    caught(Fault::NoErrorResetEmcy);
}

#[test]
fn cia301_7_5_2_18_emcy_dropped_under_the_inhibit_time_is_caught() {
    caught(Fault::InhibitedEmcyDropped);
}

#[test]
fn every_case_named_is_in_the_catalogue() {
    let catalogue = cantwin_conform::catalogue();
    for fault in Fault::ALL {
        let (id, area) = case_for(fault);
        let info = catalogue.iter().find(|c| c.id == id);
        assert!(info.is_some(), "{fault:?}: no case {id} in the catalogue");
        assert_eq!(info.unwrap().area, area, "{fault:?}: {id}");
    }
}

/// A deviation without an abort code excuses only the kind of failure it names: one for a
/// wrong value does not excuse a device that sends no boot-up (silence), nor one for a
/// missing event a PDO COB-ID change that is taken (a value).
#[test]
fn a_deviation_without_an_abort_code_excuses_only_its_kind_of_failure() {
    let listed = |case: &str, kind: &str| {
        format!(
            "[[deviation]]\ncase = \"{case}\"\nsection = \"§1\"\nbehaviour = \"x\"\nkind = \"{kind}\"\n"
        )
    };
    let id = "nmt.boot-up-reset-communication";
    let r = conform_profiled(
        Some(Fault::NoBootUpAfterResetCommunication),
        Area::Nmt,
        broken::POWERED_BEFORE,
        &listed(id, "value"),
    );
    let c = r.case(id).unwrap();
    assert_eq!(c.verdict, Verdict::Fail, "{}", c.detail);
    let id = "pdo.cob-id-change-valid";
    let r = conform_profiled(
        Some(Fault::PdoCobIdChangeWhileValid),
        Area::Pdo,
        broken::POWERED_BEFORE,
        &listed(id, "event"),
    );
    let c = r.case(id).unwrap();
    assert_eq!(c.verdict, Verdict::Fail, "{}", c.detail);
    // Named with its kind, the same failure is the listed deviation.
    let r = conform_profiled(
        Some(Fault::PdoCobIdChangeWhileValid),
        Area::Pdo,
        broken::POWERED_BEFORE,
        &listed(id, "value"),
    );
    let c = r.case(id).unwrap();
    assert_eq!(c.verdict, Verdict::Deviation, "{}", c.detail);
}

#[test]
fn a_deviation_for_silence_or_without_its_kind_is_refused() {
    for body in [
        "kind = \"silence\"\n",
        "",
        "kind = \"abort\"\n",
        "abort = 0x05040001\nkind = \"value\"\n",
    ] {
        let text = format!(
            "[[deviation]]\ncase = \"nmt.boot-up-reset-communication\"\nsection = \"§1\"\nbehaviour = \"x\"\n{body}"
        );
        assert!(
            matches!(
                cantwin_conform::ProfileFile::parse(&text),
                Err(cantwin_conform::ProfileError::Excuse(..))
            ),
            "{body}"
        );
    }
}
