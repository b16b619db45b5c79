//! The solution's [`Ranks`] over MPI (feature `mpi`; rsmpi over the distribution's OpenMPI). Only the thread
//! that initialised MPI calls it (the solution talks to the other ranks from its calling thread alone; rayon's
//! threads compute), so MPI's `Funneled` threading level suffices.

use super::ranks::Ranks;
use mpi::datatype::PartitionMut;
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::*;

/// The ranks of an MPI communicator.
pub struct MpiRanks {
    comm: SimpleCommunicator,
}

impl MpiRanks {
    /// The ranks of `comm` (MPI's world, usually).
    pub fn new(comm: SimpleCommunicator) -> Self {
        Self { comm }
    }
}

impl Ranks for MpiRanks {
    fn rank(&self) -> usize {
        self.comm.rank() as usize
    }

    fn size(&self) -> usize {
        self.comm.size() as usize
    }

    fn exchange(&self, partner: usize, mine: &[f64]) -> Vec<f64> {
        let other = self.comm.process_at_rank(partner as i32);
        let mut theirs = vec![0.0; mine.len()];
        mpi::point_to_point::send_receive_into(mine, &other, &mut theirs[..], &other);
        theirs
    }

    fn max_in_place(&self, v: &mut [f64]) {
        let mine = v.to_vec();
        self.comm
            .all_reduce_into(&mine[..], v, mpi::collective::SystemOperation::max());
    }

    fn gather_all(&self, mine: &[f64]) -> Vec<Vec<f64>> {
        let size = self.size();
        let mut counts = vec![0i32; size];
        self.comm
            .all_gather_into(&(mine.len() as i32), &mut counts[..]);
        let displs: Vec<i32> = counts
            .iter()
            .scan(0i32, |at, c| {
                let d = *at;
                *at += c;
                Some(d)
            })
            .collect();
        let total: i32 = counts.iter().sum();
        let mut all = vec![0.0; total as usize];
        {
            let mut parts = PartitionMut::new(&mut all[..], &counts[..], &displs[..]);
            self.comm.all_gather_varcount_into(mine, &mut parts);
        }
        counts
            .iter()
            .zip(&displs)
            .map(|(c, d)| all[*d as usize..(*d + *c) as usize].to_vec())
            .collect()
    }
}
