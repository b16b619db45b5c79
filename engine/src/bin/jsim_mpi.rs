//! `jsim-mpi` (feature `mpi`): the `jsim` command line started on MPI ranks — `mpirun -np 4 jsim-mpi solve
//! …`, or `srun` in a Slurm job (`jsim solve --emit-slurm`). Every rank runs the same command on the same
//! input; the astrometric solution's conjugate gradients share the sources out by sky tile and reduce the
//! rest (engine::solution::ranks), every rank ends with the same solution, and rank 0 alone writes.
//! On more than one rank only the commands that solve (solve, solve-synthetic) run: the others would write
//! the same files from every rank.

#[path = "jsim/main.rs"]
mod jsim;
// the command line's modules where its `crate::` paths look for them
pub(crate) use jsim::*;

use engine::solution::mpi::MpiRanks;
use engine::solution::ranks::{self, Ranks};
use mpi::Threading;

/// The commands that run on more than one rank.
const DISTRIBUTED: [&str; 2] = ["solve", "solve-synthetic"];

fn main() {
    // the solution talks to the other ranks from this thread alone (rayon's threads only compute)
    let Some((universe, _)) = mpi::initialize_with_threading(Threading::Funneled) else {
        eprintln!("jsim-mpi: error: MPI could not be initialised (start it with mpirun or srun)");
        std::process::exit(1);
    };
    let world = MpiRanks::new(universe.world());
    let command = std::env::args().nth(1).unwrap_or_default();
    if world.size() > 1 && !DISTRIBUTED.contains(&command.as_str()) {
        if world.rank() == 0 {
            eprintln!(
                "jsim-mpi: error: `{command}` runs on one rank (here {}): on several, only {} run",
                world.size(),
                DISTRIBUTED.join(" and ")
            );
        }
        std::process::exit(2);
    }
    ranks::set_world(std::rc::Rc::new(world));
    jsim::main();
    // the universe ends here: MPI is finalised after the command returns
    drop(universe);
}
