//! An interrupt that comes while another thread still fills a temporary
//! folder (a checkpoint being written when the second Ctrl-C comes) removes
//! the folder whole (its own process: the registry is process-wide).
#![allow(clippy::unwrap_used)]
#[test]
fn a_folder_being_filled_is_removed_whole() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path().join(".tmp-step-000000050-1");
    let guard = mfm_files::interrupt::TemporaryDir::register(&tmp);
    std::fs::create_dir(&tmp).unwrap();
    let writing = tmp.clone();
    let writer = std::thread::spawn(move || {
        let mut made = 0;
        for i in 0..500 {
            if std::fs::write(writing.join(format!("part-{i}.bin")), [0u8; 64]).is_err() {
                break;
            }
            made += 1;
        }
        made
    });
    while std::fs::read_dir(&tmp).map_or(0, |d| d.count()) < 20 {
        std::thread::yield_now();
    }
    assert_eq!(mfm_files::interrupt::clean_up_temporaries(), 1);
    assert!(!tmp.exists(), "the folder being filled was left behind");
    let made = writer.join().unwrap();
    assert!(made >= 20, "{made}");
    assert!(!tmp.exists());
    drop(guard);
}
