//! The on-board program: reads framed messages from a byte link, drives the
//! core traverse and answers with results. `no_std`, no allocation.
#![no_std]
