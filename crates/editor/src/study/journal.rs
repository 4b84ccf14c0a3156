//! A participant's answers, journalled as they are given: one JSON line per
//! answer in `answers/<participant>.jsonl`, after a header line naming the
//! study build. Each line is flushed to disk before the next avatar shows,
//! so a crash, a kill or a dropped SSH connection loses nothing; starting
//! again resumes at the first avatar not answered. A line cut short by a
//! crash mid-write is dropped on reopening.

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::design::{check_participant, StudyFolder, ANSWERS_DIR};
use super::results::{AvatarResult, Results};
use crate::compose::composition::{Composition, StudyGroup};
use crate::error::{Error, Result};

/// The first line of a journal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// The participant's ID.
    pub participant: String,
    /// Fingerprint of the study build the answers belong to.
    pub study: String,
}

/// One answer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Answer {
    /// The avatar's number.
    pub avatar: u32,
    /// "Is this face edited?"
    pub edited: bool,
    /// The regions flagged as edited (empty for "no").
    #[serde(default)]
    pub regions: Vec<StudyGroup>,
    /// Seconds the avatar was on screen before the answer.
    pub seconds: f64,
    /// The camera yaw when answering, degrees.
    pub yaw_deg: f32,
    /// The camera pitch when answering, degrees.
    pub pitch_deg: f32,
}

/// A participant's journal, open for appending.
pub struct Journal {
    file: File,
    path: PathBuf,
    /// Answers given so far, in order.
    pub answers: Vec<Answer>,
}

/// Where a participant's journal lives.
pub fn journal_path(study: &StudyFolder, participant: &str) -> PathBuf {
    study
        .dir
        .join(ANSWERS_DIR)
        .join(format!("{participant}.jsonl"))
}

impl Journal {
    /// Opens (or starts) a participant's journal.
    pub fn open(study: &StudyFolder, participant: &str) -> Result<Journal> {
        check_participant(participant)?;
        let path = journal_path(study, participant);
        // The answers file is ours to write: failing to is an I/O error (exit 4).
        let io = |e: std::io::Error| Error::Io(format!("{}: {e}", path.display()));
        let header = Header {
            participant: participant.to_string(),
            study: study.fingerprint.clone(),
        };
        let answers = if path.exists() {
            let (read, complete_len) = read_journal(&path)?;
            if read.header != header {
                return Err(Error::input(format!(
                    "{} was recorded for another build of this study (or another participant); move it away to start again",
                    path.display()
                )));
            }
            // Drop a line cut short by a crash, so the next answer starts clean.
            let file = OpenOptions::new().write(true).open(&path).map_err(io)?;
            file.set_len(complete_len).map_err(io)?;
            read.answers
        } else {
            let mut file = File::create(&path).map_err(io)?;
            let line = serde_json::to_string(&header).expect("headers serialise");
            writeln!(file, "{line}").map_err(io)?;
            file.sync_all().map_err(io)?;
            Vec::new()
        };
        let file = OpenOptions::new().append(true).open(&path).map_err(io)?;
        Ok(Journal {
            file,
            path,
            answers,
        })
    }

    /// Appends an answer and waits until it is on disk.
    pub fn record(&mut self, answer: Answer) -> Result<()> {
        let line = serde_json::to_string(&answer).expect("answers serialise");
        writeln!(self.file, "{line}")
            .and_then(|_| self.file.sync_data())
            .map_err(|e| {
                Error::input(format!(
                    "cannot journal the answer to {}: {e}",
                    self.path.display()
                ))
            })?;
        self.answers.push(answer);
        Ok(())
    }

    /// True when the avatar has been answered.
    pub fn answered(&self, avatar: u32) -> bool {
        self.answers.iter().any(|a| a.avatar == avatar)
    }
}

/// A journal as read back.
pub struct ReadJournal {
    /// Its header.
    pub header: Header,
    /// Its complete answer lines.
    pub answers: Vec<Answer>,
}

/// Reads a journal; returns it and the length of its complete lines.
fn read_journal(path: &Path) -> Result<(ReadJournal, u64)> {
    let bad = |what: String| Error::input(format!("{}: {what}", path.display()));
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let complete = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    let text = std::str::from_utf8(&bytes[..complete]).map_err(|_| bad("not UTF-8".into()))?;
    let mut lines = text.lines();
    let header: Header = lines
        .next()
        .and_then(|l| serde_json::from_str(l).ok())
        .ok_or_else(|| bad("not a visage study journal (no header line)".into()))?;
    let answers = lines
        .enumerate()
        .map(|(i, l)| serde_json::from_str(l).map_err(|e| bad(format!("line {}: {e}", i + 2))))
        .collect::<Result<Vec<Answer>>>()?;
    Ok((ReadJournal { header, answers }, complete as u64))
}

/// Every participant's journal in a study folder, by participant.
pub fn read_all(study: &StudyFolder) -> Result<BTreeMap<String, Vec<Answer>>> {
    let dir = study.dir.join(ANSWERS_DIR);
    let mut all = BTreeMap::new();
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Ok(all);
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.extension().is_none_or(|x| x != "jsonl") {
            continue;
        }
        let (journal, _) = read_journal(&path)?;
        if journal.header.study != study.fingerprint {
            return Err(Error::input(format!(
                "{} was recorded for another build of this study",
                path.display()
            )));
        }
        all.insert(journal.header.participant, journal.answers);
    }
    Ok(all)
}

/// Tallies every journal into per-avatar results (a participant's last
/// answer to an avatar counts).
pub fn tally(study: &StudyFolder) -> Result<Results> {
    let journals = read_all(study)?;
    let mut avatars = Vec::new();
    for avatar in &study.study.avatars {
        let recipe = study.recipe(avatar)?;
        let composition = Composition::of_recipe(&recipe);
        let answers: Vec<&Answer> = journals
            .values()
            .filter_map(|list| list.iter().rev().find(|a| a.avatar == avatar.id))
            .collect();
        let n = answers.len() as u32;
        let share = |count: usize| if n == 0 { 0.0 } else { count as f64 / n as f64 };
        let regions = StudyGroup::EDITABLE
            .into_iter()
            .map(|g| {
                let kept = answers.iter().filter(|a| !a.regions.contains(&g)).count();
                (g, share(kept))
            })
            .collect();
        avatars.push(AvatarResult {
            id: avatar.id,
            category: avatar.category.clone(),
            base: composition.base.clone(),
            groups: composition.groups.clone(),
            unplaced: composition.unplaced.clone(),
            authenticity: share(answers.iter().filter(|a| !a.edited).count()),
            regions,
            answers: Some(n),
            excluded: Vec::new(),
            note: None,
        });
    }
    Ok(Results {
        participants: Some(journals.len() as u32),
        avatars,
    })
}
