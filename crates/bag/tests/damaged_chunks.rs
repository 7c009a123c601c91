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

/// Regression (issue 61): `bag recover` copied a corrupted schema record (outside any chunk, so no
/// checksum covers it) into a bag that `bag info` then called complete. A channel whose schema is
/// not a message definition is now left out and reported with its message count; the other
/// channels are recovered.
#[test]
fn a_damaged_schema_outside_the_chunks_is_reported_and_its_channel_left_out() {
    let dir = scratch("damaged_schema");
    let opts = WriterOptions { compression: equiarm_bag::Compression::None, chunk_size: 2 << 10, ..Default::default() };
    let mut w = Writer::create(&dir.join("bag"), opts).unwrap();
    let qos = [equiarm_bag::qos::OfferedQos::reliable(10)];
    let cmd = w.add_topic(TopicInfo::of::<GripperCommand>("/env0/gripper_cmd", &qos)).unwrap();
    let ep = w.add_topic(TopicInfo::of::<equiarm_msgs::msg::EpisodeResult>("/episodes", &qos)).unwrap();
    for k in 0..N {
        let t = T0 + k as u64 * 1_000_000;
        let m = GripperCommand { obs_seq: k as u64, ..Default::default() };
        w.write(cmd, t, t, &cdr::encode(&m).unwrap()).unwrap();
        let e = equiarm_msgs::msg::EpisodeResult { episode: k, ..Default::default() };
        w.write(ep, t, t, &cdr::encode(&e).unwrap()).unwrap();
    }
    let s = w.finish().unwrap();
    let file = s.dir.join(&s.files[0]);
    let mut bytes = std::fs::read(&file).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let in_chunk = |at: usize| {
        summary
            .chunk_indexes
            .iter()
            .any(|c| (c.chunk_start_offset..c.chunk_start_offset + c.chunk_length).contains(&(at as u64)))
    };
    // every copy of the command's definition outside the chunks loses a bit (no longer UTF-8)
    let needle = b"uint64 obs_seq";
    let hits: Vec<usize> =
        (0..bytes.len() - needle.len()).filter(|&i| &bytes[i..i + needle.len()] == needle && !in_chunk(i)).collect();
    assert!(!hits.is_empty(), "the definition is stored outside the chunks");
    for i in hits {
        bytes[i + 7] ^= 0x80;
    }
    std::fs::write(&file, &bytes).unwrap();

    let out = dir.join("recovered");
    let r = recover(&s.dir, &out, WriterOptions::default()).unwrap();
    assert_eq!(r.damaged_channels.len(), 1, "{:?}", r.damaged_channels);
    let d = &r.damaged_channels[0];
    assert_eq!((d.topic.as_str(), d.messages), ("/env0/gripper_cmd", N as u64), "{d:?}");
    assert!(d.reason.contains("not UTF-8"), "{}", d.reason);
    let info = Reader::open(&out).unwrap().info().unwrap();
    assert_eq!(info.topics.keys().collect::<Vec<_>>(), ["/episodes"], "only the intact channel is copied");
    assert_eq!(info.messages, N as u64);
}

/// Regression (issue 61): `bag recover` said nothing about a file `metadata.yaml` lists but that is
/// gone from the bag directory; it now reports it (its messages are lost), and recovers the rest.
#[test]
fn recover_reports_a_listed_file_that_is_missing() {
    let dir = scratch("missing_split");
    let s = bag_with(&dir, WriterOptions { chunk_size: 2 << 10, split_bytes: Some(6 << 10), ..Default::default() });
    assert!(s.files.len() >= 3, "{:?}", s.files);
    let gone = s.dir.join(&s.files[1]);
    let lost = Reader::open(&gone).unwrap().info().unwrap().messages;
    std::fs::remove_file(&gone).unwrap();
    let r = recover(&s.dir, &dir.join("recovered"), WriterOptions::default()).unwrap();
    assert_eq!(r.missing_files, vec![s.files[1].clone()]);
    assert_eq!(r.summary.messages, N as u64 - lost);
}

/// Regression (issue 61): a directory where a bag file belongs (`NAME_0.mcap/`) was reported as "No
/// such device (os error 19)"; the error names it as a directory.
#[test]
fn a_directory_named_like_a_bag_file_is_named_as_a_directory() {
    let dir = scratch("dir_for_file");
    std::fs::create_dir_all(dir.join("bag").join("bag_0.mcap")).unwrap();
    let e = Reader::open(&dir.join("bag")).err().unwrap().to_string();
    assert!(e.contains("bag_0.mcap: is a directory, where a file was expected"), "{e}");
}
