//! Edits between materials (`material.transfer`).

pub mod transfer;
