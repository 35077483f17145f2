// `microbsdf plan JOB.toml [--json plan.json]`: what a job will compute and cost — tiles, the
// effects planner's decisions, core-hours, memory, output size and the error each budget buys —
// from short pilots (job/plan.h).
#include <chrono>
#include <iostream>

#include <tbb/task_arena.h>

#include "cluster/mpi_session.h"
#include "cluster/output_schema_of.h"
#include "cmd/command.h"
#include "core/log.h"
#include "core/stop.h"
#include "io/bsdf_file.h"
#include "job/job.h"
#include "job/plan.h"

namespace mbsdf {

Command addPlanCommand(CLI::App& app) {
  struct Options {
    std::string jobPath, json;
    int threads = 0;
  };
  auto o = std::make_shared<Options>();
  Command c;
  c.app = app.add_subcommand("plan",
                             "what a job will compute and cost (tiles, core-hours, output size), from a short pilot");
  c.app->add_option("job", o->jobPath, "job file (TOML)")->required();
  c.app->add_option("--json", o->json, "also write the plan as JSON to this file");
  addThreadsOption(c.app, o->threads, "threads for the pilot (default: all cores)");
  c.run = [o] {
    auto since = [](std::chrono::steady_clock::time_point t0) {
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    };
    // MPI_Init as every rank of the run meets it, timed for the estimate (0.3 s for one process
    // here: half of a small job's run). TBB counts its cores first, as `run` has it, before MPI's
    // hardware discovery moves this thread from core to core.
    tbb::this_task_arena::max_concurrency();
    const auto starting = std::chrono::steady_clock::now();
    MpiSession mpi(nullptr, nullptr);
    const double mpiStartSeconds = since(starting);
    installStopHandlers();
    setupLogging(0, "", "", false);
    const auto loading = std::chrono::steady_clock::now();
    Job job = loadJob(o->jobPath);
    PlanOptions po;
    po.jobLoadSeconds = since(loading);
    po.mpiStartSeconds = mpiStartSeconds;
    po.threads = o->threads;
    po.writeSecondsPerSlice = [](const Job& j, const DirectionGrid& g, int slicesPerCommit) {
      return measureWriteSecondsPerSlice(outputSchemaOf(j), g, slicesPerCommit);
    };
    po.storedBytesPerSlice = [](const Job& j, const DirectionGrid& g, const std::vector<TileResult>& tiles) {
      return storedBytesPerSlice(outputSchemaOf(j), g, tiles);
    };
    nlohmann::json p = planJob(job, po);
    std::cout << formatPlan(p);
    if (!o->json.empty()) writeJsonFile(o->json, p, 2);
    return 0;
  };
  return c;
}

}  // namespace mbsdf
