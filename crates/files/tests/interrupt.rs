//! An interrupted command leaves nothing of its own (its own process: the
//! registry is process-wide).
#![allow(clippy::unwrap_used)]
#[test]
fn an_interrupted_command_leaves_nothing_of_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let mine = dir.path().join("mine.txt");
    std::fs::write(&mine, "the user's").unwrap();
    let out = dir.path().join("out");
    let undo = mfm_files::Undo::empty_folder(&out).unwrap();
    std::fs::write(out.join("part.ply"), "half").unwrap();
    let mut file = mfm_files::AtomicFile::create(dir.path().join("big.npy")).unwrap();
    std::io::Write::write_all(&mut file, b"half").unwrap();
    let lock = mfm_files::FolderLock::acquire(&out, "test").unwrap();
    assert!(mfm_files::interrupt::clean_up() >= 3);
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("mine.txt")], "{left:?}");
    // what was cleaned up is not touched again
    undo.keep();
    drop(file);
    drop(lock);
    assert_eq!(mfm_files::interrupt::clean_up(), 0);
}
