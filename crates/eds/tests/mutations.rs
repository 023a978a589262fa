//! Property tests: corpus files with lines deleted, duplicated, altered or swapped, random
//! bytes inserted, or cut short never make the parser panic; whatever parses writes and
//! re-parses equal, and the checks, the docs and the conversion to an object dictionary
//! run on it without panicking.
#![allow(clippy::unwrap_used)]

use cantwin_eds::{load, load_bytes, parse, parse_bytes, render_markdown, to_od, write};
use proptest::prelude::*;
use std::path::PathBuf;

fn corpus() -> Vec<Vec<u8>> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let mut files: Vec<_> = [dir.clone(), dir.join("irregular")]
        .iter()
        .flat_map(|d| std::fs::read_dir(d).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("eds" | "dcf")))
        .collect();
    files.sort();
    files.iter().map(|p| std::fs::read(p).unwrap()).collect()
}

#[derive(Debug, Clone)]
enum Mutation {
    Delete(usize),
    Duplicate(usize),
    Replace(usize, String),
    Swap(usize, usize),
    InsertBytes(usize, Vec<u8>),
    Truncate(usize),
    /// Replaces the value of a `key=value` line.
    Value(usize, String),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let text = "[ -~\\[\\]=;$]{0,24}";
    let value = prop_oneof![
        Just("$NODEID+0x180".to_owned()),
        Just("0x".to_owned()),
        Just("-1".to_owned()),
        Just("0xFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFF".to_owned()),
        Just("99999999999999999999999999999999999999999".to_owned()),
        Just("NaN".to_owned()),
        Just("0x7FC00001".to_owned()),
        Just(String::new()),
        Just("0x0009".to_owned()),
        Just("0x000F".to_owned()),
        Just("0x8".to_owned()),
        Just("255".to_owned()),
        "[0-9a-fA-Fx$+ -]{0,12}",
    ];
    prop_oneof![
        any::<usize>().prop_map(Mutation::Delete),
        any::<usize>().prop_map(Mutation::Duplicate),
        (any::<usize>(), text).prop_map(|(i, s)| Mutation::Replace(i, s)),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::Swap(a, b)),
        (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(i, b)| Mutation::InsertBytes(i, b)),
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), value.clone()).prop_map(|(i, v)| Mutation::Value(i, v)),
        (any::<usize>(), value).prop_map(|(i, v)| Mutation::Value(i, v)),
    ]
}

fn apply(bytes: &[u8], m: &Mutation) -> Vec<u8> {
    let mut lines: Vec<Vec<u8>> = bytes.split(|b| *b == b'\n').map(<[u8]>::to_vec).collect();
    let n = lines.len();
    match m {
        Mutation::Delete(i) => {
            lines.remove(i % n);
        }
        Mutation::Duplicate(i) => {
            let l = lines[i % n].clone();
            lines.insert(i % n, l);
        }
        Mutation::Replace(i, s) => lines[i % n] = s.clone().into_bytes(),
        Mutation::Swap(a, b) => lines.swap(a % n, b % n),
        Mutation::Value(i, v) => {
            let l = &mut lines[i % n];
            if let Some(eq) = l.iter().position(|b| *b == b'=') {
                l.truncate(eq + 1);
                l.extend_from_slice(v.as_bytes());
            }
        }
        Mutation::InsertBytes(i, b) => {
            let mut out = bytes.to_vec();
            let at = i % (out.len() + 1);
            out.splice(at..at, b.iter().copied());
            return out;
        }
        Mutation::Truncate(i) => return bytes[..i % (bytes.len() + 1)].to_vec(),
    }
    lines.join(&b'\n')
}

/// Whatever parses must survive the rest of the pipeline unchanged.
fn pipeline(bytes: &[u8]) -> Result<(), TestCaseError> {
    let line_count = bytes.split(|b| *b == b'\n').count();
    match parse_bytes(bytes) {
        Err(e) => {
            prop_assert!(
                e.line >= 1 && e.line <= line_count,
                "line {} of {}",
                e.line,
                line_count
            );
            prop_assert!(!e.to_string().is_empty());
        }
        Ok(eds) => {
            let text = write(&eds);
            let back = parse(&text);
            prop_assert_eq!(back.as_ref(), Ok(&eds), "rewritten:\n{}", text);
            let _ = eds.check();
            let _ = render_markdown(&eds);
            let _ = to_od(&eds);
        }
    }
    Ok(())
}

/// Any input loads: every diagnostic names a line of the file (or none), the dictionary is
/// built or refused without a panic, and once written the text is stable.
fn lenient(bytes: &[u8]) -> Result<(), TestCaseError> {
    let line_count = bytes.split(|b| *b == b'\n').count();
    let loaded = load_bytes(bytes);
    for i in &loaded.report.issues {
        prop_assert!(i.line.is_none_or(|l| l >= 1 && l <= line_count), "{}", i);
    }
    let _ = to_od(&loaded.eds);
    let text = write(&loaded.eds);
    let again = write(&load(&text).eds);
    prop_assert_eq!(&again, &text);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn mutated_corpus_never_panics_and_round_trips(
        file in 0usize..32,
        muts in proptest::collection::vec(mutation(), 1..4),
    ) {
        let files = corpus();
        let mut bytes = files[file % files.len()].clone();
        for m in &muts {
            bytes = apply(&bytes, m);
        }
        pipeline(&bytes)?;
        lenient(&bytes)?;
    }

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        pipeline(&bytes)?;
    }

    #[test]
    fn random_ini_lines_never_panic(lines in proptest::collection::vec("[ -~]{0,30}", 0..40)) {
        let mut text = String::from("[2000]\n");
        text.push_str(&lines.join("\n"));
        pipeline(text.as_bytes())?;
        lenient(text.as_bytes())?;
    }
}
