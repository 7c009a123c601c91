//! Regression (issue 28, found by `equiarm_fuzz bag_read` and `bag_recover`): a damaged record
//! length inside a chunk made the reader (mcap's `ChunkReader`) reserve that many bytes before
//! finding the chunk short, so one flipped byte aborted `bag info`, `play`, `eval` and `recover`
//! with "memory allocation of … bytes failed". Now such a chunk is lost like any damaged chunk.

use std::path::{Path, PathBuf};

use equiarm_bag::{Compression, ReadMode, Reader, TopicInfo, Writer, WriterOptions, recover};
use equiarm_msgs::cdr;
use equiarm_msgs::msg::GripperCommand;

const T0: u64 = 1_700_000_000_000_000_000;
const N: u64 = 60;

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("record_lengths").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// An uncompressed bag of `N` commands in small chunks; its one file's bytes, with the length of
/// the message record of command `victim` set to `len`.
fn bag_with_record_length(dir: &Path, victim: u64, len: u64) -> PathBuf {
    let opts = WriterOptions { compression: Compression::None, chunk_size: 1 << 10, ..Default::default() };
    let mut w = Writer::create(&dir.join("bag"), opts).unwrap();
    let id = w.add_topic(TopicInfo::of::<GripperCommand>("/env0/gripper_cmd", &[])).unwrap();
    let payload = |k: u64| cdr::encode(&GripperCommand { obs_seq: 0xabcd_0000 + k, ..Default::default() }).unwrap();
    for k in 0..N {
        let t = T0 + k * 1_000_000;
        w.write(id, t, t, &payload(k)).unwrap();
    }
    let s = w.finish().unwrap();
    let file = s.dir.join(&s.files[0]);
    let mut bytes = std::fs::read(&file).unwrap();
    let data = payload(victim);
    let at = bytes.windows(data.len()).position(|w| w == data.as_slice()).expect("the message in the file");
    // a message record: opcode, u64 length, channel id (2), sequence (4), log and publish time (8 + 8), data
    let record = at - (2 + 4 + 8 + 8) - 9;
    assert_eq!(bytes[record], 0x05, "a message record opcode");
    bytes[record + 1..record + 9].copy_from_slice(&len.to_le_bytes());
    let bad = dir.join("bad.mcap");
    std::fs::write(&bad, bytes).unwrap();
    bad
}

#[test]
fn a_huge_record_length_inside_a_chunk_loses_the_chunk_instead_of_aborting() {
    for (name, len) in [("64tib", 1u64 << 46), ("max", u64::MAX), ("past_chunk", 4096)] {
        let dir = scratch(name);
        let bad = bag_with_record_length(&dir, N / 2, len);
        let r = Reader::open(&bad).unwrap();
        assert!(r.for_each(ReadMode::Strict, |_| Ok::<(), ()>(())).is_err(), "{name}: strict mode fails");
        let mut got = 0u64;
        let report = r
            .for_each(ReadMode::Salvage, |_| {
                got += 1;
                Ok::<(), ()>(())
            })
            .unwrap()
            .unwrap();
        assert_eq!(report.lost.len(), 1, "{name}: one chunk lost: {:?}", report.lost);
        assert!(got > N / 2 && got < N, "{name}: the other chunks are read ({got} of {N})");
        let info = r.info().unwrap();
        assert_eq!((info.messages, info.lost.len()), (got, 1), "{name}");

        let out = recover(&bad, &dir.join("recovered"), WriterOptions::default()).unwrap();
        assert_eq!((out.summary.messages, out.lost.len()), (got, 1), "{name}");
    }
}
