//! Regression (issue 28): one corrupt chunk made `bag info/eval/play` fail and `bag recover` stop,
//! dropping every intact chunk after it. Now a damaged chunk is skipped whole and reported (file,
//! time range, message count from the index), and every other chunk is read and recovered.

use std::path::{Path, PathBuf};

use equiarm_bag::{BagError, ReadMode, Reader, TopicInfo, Writer, WriterOptions, recover};
use equiarm_msgs::cdr;
use equiarm_msgs::msg::GripperCommand;

const T0: u64 = 1_700_000_000_000_000_000;
const N: u32 = 400;

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("damaged_chunks").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A bag of `N` commands (obs_seq = index) in chunks of about 2 KiB; returns its one file.
fn bag(dir: &Path) -> PathBuf {
    let s = bag_with(dir, WriterOptions { chunk_size: 2 << 10, ..Default::default() });
    assert_eq!(s.files.len(), 1);
    s.dir.join(&s.files[0])
}

/// The bag of `N` commands written with `opts` into `dir/bag`.
fn bag_with(dir: &Path, opts: WriterOptions) -> equiarm_bag::BagSummary {
    let mut w = Writer::create(&dir.join("bag"), opts).unwrap();
    let id = w
        .add_topic(TopicInfo::of::<GripperCommand>("/env0/gripper_cmd", &[equiarm_bag::qos::OfferedQos::reliable(10)]))
        .unwrap();
    for k in 0..N {
        let m = GripperCommand { obs_seq: k as u64, dx: 0.01, ..Default::default() };
        let t = T0 + k as u64 * 1_000_000;
        w.write(id, t, t, &cdr::encode(&m).unwrap()).unwrap();
    }
    w.finish().unwrap()
}

/// The bytes of `file` with chunk `k` damaged (8 bytes flipped in the middle of its compressed
/// data), the file's summary, and how many messages that chunk holds.
fn damaged(file: &Path, k: usize) -> (Vec<u8>, mcap::Summary, usize) {
    let mut bytes = std::fs::read(file).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(summary.chunk_indexes.len() >= 5, "{} chunks", summary.chunk_indexes.len());
    let victim = &summary.chunk_indexes[k];
    let in_victim = summary.read_message_indexes(&bytes, victim).unwrap().values().map(Vec::len).sum::<usize>();
    assert!(in_victim > 0);
    let mid = (victim.chunk_start_offset + victim.chunk_length / 2) as usize;
    for b in &mut bytes[mid..mid + 8] {
        *b ^= 0x5a;
    }
    (bytes, summary, in_victim)
}

fn seqs(r: &Reader, mode: ReadMode) -> Result<(Vec<u64>, equiarm_bag::ReadReport), BagError> {
    let mut got = Vec::new();
    let report = r.for_each(mode, |m| {
        got.push(cdr::decode::<GripperCommand>(m.data).unwrap().obs_seq);
        Ok::<(), ()>(())
    })?;
    Ok((got, report.unwrap()))
}

#[test]
fn a_damaged_chunk_loses_only_its_own_messages_in_reading_and_recovery() {
    let dir = scratch("one_bad_chunk");
    let (bytes, summary, in_victim) = damaged(&bag(&dir), 2);
    let victim = &summary.chunk_indexes[2];
    let bad = dir.join("bad.mcap");
    std::fs::write(&bad, &bytes).unwrap();

    let r = Reader::open(&bad).unwrap();
    let e = seqs(&r, ReadMode::Strict).unwrap_err();
    assert!(matches!(e, BagError::CorruptChunk { offset: Some(_), .. }) && e.to_string().contains("bad.mcap"), "{e}");

    let (got, report) = seqs(&r, ReadMode::Salvage).unwrap();
    assert_eq!(got.len() + in_victim, N as usize, "only the damaged chunk's messages are missing");
    assert_eq!(report.messages as usize, got.len());
    assert!(got.windows(2).all(|w| w[0] < w[1]), "the other chunks come in order");
    assert!(got.contains(&(N as u64 - 1)), "chunks after the damaged one are read");
    assert_eq!(report.lost.len(), 1, "{:?}", report.lost);
    let lost = &report.lost[0];
    assert_eq!(lost.messages, Some(in_victim as u64));
    assert_eq!((lost.start, lost.end), (victim.message_start_time, victim.message_end_time));
    assert_eq!(lost.offset, Some(victim.chunk_start_offset));

    let info = r.info().unwrap();
    assert_eq!(info.messages as usize, got.len());
    assert_eq!(info.lost.len(), 1);
    assert_eq!(info.files[0].messages as usize, got.len(), "the file's count is what was readable");
    assert!(info.files[0].complete && info.files[0].compression == "zstd", "{:?}", info.files[0]);

    let out = dir.join("recovered");
    let rec = recover(&bad, &out, WriterOptions::default()).unwrap();
    assert_eq!(rec.summary.messages as usize, got.len());
    assert_eq!(rec.lost.len(), 1);
    let (again, report) = seqs(&Reader::open(&out).unwrap(), ReadMode::Strict).unwrap();
    assert_eq!(again, got);
    assert!(report.lost.is_empty() && report.truncated.is_empty());
}

#[test]
fn a_damaged_chunk_in_a_file_without_footer_is_skipped_too() {
    let dir = scratch("cut_and_bad");
    let (bytes, summary, in_victim) = damaged(&bag(&dir), 1);
    // cut the summary and footer off: read record by record
    let data_end = summary.chunk_indexes.iter().map(|c| c.chunk_start_offset + c.chunk_length).max().unwrap() as usize;
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..data_end]).unwrap();
    let (got, report) = seqs(&Reader::open(&cut).unwrap(), ReadMode::Salvage).unwrap();
    assert_eq!(report.lost.len(), 1, "{report:?}");
    assert_eq!(report.lost[0].offset, None);
    assert_eq!(report.truncated.len(), 1, "no footer: {report:?}");
    // every chunk but the damaged one (the message indexes after the last chunk were cut too)
    assert_eq!(got.len() + in_victim, N as usize);
}

/// Regression (issue 61): a 0-byte split file (a recorder killed right at a split, or a full disk)
/// made `bag recover`, `bag info` and `bag eval` refuse the whole bag, intact files included. It is
/// skipped and reported as truncated; the other files are read and recovered; a directory of only
/// empty files, and a single empty file, are still refused.
#[test]
fn an_empty_split_file_is_reported_and_the_other_files_are_read() {
    let dir = scratch("empty_split");
    let s = bag_with(&dir, WriterOptions { chunk_size: 2 << 10, split_bytes: Some(6 << 10), ..Default::default() });
    assert!(s.files.len() >= 3, "{:?}", s.files);
    let emptied = s.dir.join(&s.files[1]);
    let lost = Reader::open(&emptied).unwrap().info().unwrap().messages;
    std::fs::write(&emptied, b"").unwrap();

    let info = Reader::open(&s.dir).unwrap().info().unwrap();
    assert_eq!(info.messages, N as u64 - lost);
    assert_eq!(info.files.len(), s.files.len(), "the empty file is listed too");
    assert_eq!((info.files[1].size, info.files[1].messages, info.files[1].complete), (0, 0, false));
    assert_eq!(info.truncated.len(), 1, "{:?}", info.truncated);
    assert!(info.truncated[0].0 == emptied && info.truncated[0].1.contains("empty (0 bytes)"));
    // metadata.yaml still lists the file: its count disagrees, and says so
    let m = info.metadata.unwrap();
    assert!(m.problems.iter().any(|p| p.contains(&format!("holds {lost} messages, it holds 0"))), "{:?}", m.problems);
    let e = Reader::open(&s.dir).unwrap().for_each(ReadMode::Strict, |_| Ok::<(), ()>(())).err().unwrap();
    assert!(matches!(e, BagError::Empty { .. }), "strict reads still refuse: {e}");

    let out = dir.join("recovered");
    let r = recover(&s.dir, &out, WriterOptions::default()).unwrap();
    assert_eq!(r.truncated.len(), 1);
    let (got, report) = seqs(&Reader::open(&out).unwrap(), ReadMode::Strict).unwrap();
    assert_eq!((got.len() as u64, report.truncated.len()), (N as u64 - lost, 0));

    for f in &s.files {
        std::fs::write(s.dir.join(f), b"").unwrap();
    }
    assert!(matches!(Reader::open(&s.dir).err().unwrap(), BagError::Empty { .. }));
}
