// `microbsdf keys [--markdown]`: every key a job file may hold, from the registry the parser reads
// (job/job_keys.h); docs/job-reference.md ends with its Markdown form.
#include <iostream>

#include "cmd/command.h"
#include "job/job_keys.h"

namespace mbsdf {

Command addKeysCommand(CLI::App& app) {
  auto markdown = std::make_shared<bool>(false);
  Command c;
  c.app = app.add_subcommand("keys", "every key a job file may hold: type, default, accepted values, meaning");
  c.app->add_flag("--markdown", *markdown, "as the Markdown table of docs/job-reference.md");
  c.run = [markdown] {
    std::cout << (*markdown ? jobKeysMarkdown() : jobKeysText());
    return 0;
  };
  return c;
}

}  // namespace mbsdf
