//! An interrupt of a command whose output holds the user's progress removes
//! the temporaries and locks only (its own process: the registry is
//! process-wide, so this is the binary's only test).
#![allow(clippy::unwrap_used)]
#[test]
fn temporaries_go_and_open_undos_stay() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let undo = mfm_files::Undo::empty_folder(&run).unwrap();
    std::fs::write(run.join("checkpoint.bin"), "progress").unwrap();
    let tmp = run.join(".tmp-step-000000100-1");
    std::fs::create_dir(&tmp).unwrap();
    std::fs::write(tmp.join("model.safetensors"), "half").unwrap();
    let guard = mfm_files::interrupt::TemporaryDir::register(&tmp);
    let mut file = mfm_files::AtomicFile::create(run.join("model.safetensors")).unwrap();
    std::io::Write::write_all(&mut file, b"half").unwrap();
    let lock = mfm_files::FolderLock::acquire(&run, "test").unwrap();
    assert_eq!(mfm_files::interrupt::clean_up_temporaries(), 3);
    let left: Vec<_> = std::fs::read_dir(&run)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        left,
        vec![std::ffi::OsString::from("checkpoint.bin")],
        "{left:?}"
    );
    assert!(!dir.path().join(".run.mfm-lock").exists());
    // the Undo is still registered: a full clean-up would undo it
    assert_eq!(mfm_files::interrupt::clean_up(), 1);
    assert!(!run.exists());
    undo.keep();
    drop(guard);
    drop(file);
    drop(lock);
    assert_eq!(mfm_files::interrupt::clean_up(), 0);
}
