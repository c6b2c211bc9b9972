//! The bounded pool that runs CPU work (decode, SIFT, quantize, vote) off the
//! async runtime: at most `workers` jobs run at once on tokio's blocking
//! threads, at most `queue` more wait for a turn, and anything beyond is
//! refused at once so that latency cannot grow without bound. A job that
//! panics is caught and reported as an error; the pool keeps working.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use tokio::sync::Semaphore;
use tokio::time::Instant;

/// Why a job did not produce its result.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PoolError {
    #[error("all workers busy and the queue full")]
    QueueFull,
    #[error("the deadline passed while waiting for a worker")]
    TimedOut,
    #[error("the job panicked: {0}")]
    Panicked(String),
}

/// A bounded worker pool; cheap to clone (clones share the pool).
#[derive(Clone)]
pub struct WorkerPool {
    /// One permit per worker.
    running: Arc<Semaphore>,
    /// One permit per job admitted (running or waiting).
    admitted: Arc<Semaphore>,
    workers: usize,
    queue: usize,
}

impl WorkerPool {
    pub fn new(workers: usize, queue: usize) -> Self {
        let workers = workers.max(1);
        Self {
            running: Arc::new(Semaphore::new(workers)),
            admitted: Arc::new(Semaphore::new(workers + queue)),
            workers,
            queue,
        }
    }

    pub fn workers(&self) -> usize {
        self.workers
    }

    pub fn queue_capacity(&self) -> usize {
        self.queue
    }

    /// Jobs admitted and not finished (running or waiting).
    pub fn admitted(&self) -> usize {
        self.workers + self.queue - self.admitted.available_permits()
    }

    /// Jobs running now.
    pub fn busy(&self) -> usize {
        self.workers - self.running.available_permits()
    }

    /// Run `job` on a worker once one is free. Refused at once with
    /// [`PoolError::QueueFull`] when `workers + queue` jobs are admitted; gives
    /// up with [`PoolError::TimedOut`] if `deadline` passes before a worker is
    /// free. Once started the job runs to its end even if the caller goes
    /// away, holding its places until then.
    pub async fn run<T, F>(&self, deadline: Option<Instant>, job: F) -> Result<T, PoolError>
    where
        T: Send + 'static,
        F: FnOnce() -> T + Send + 'static,
    {
        let ticket = self
            .admitted
            .clone()
            .try_acquire_owned()
            .map_err(|_| PoolError::QueueFull)?;
        let acquire = self.running.clone().acquire_owned();
        let permit = match deadline {
            Some(d) => tokio::time::timeout_at(d, acquire)
                .await
                .map_err(|_| PoolError::TimedOut)?,
            None => acquire.await,
        }
        .expect("the pool's semaphores are never closed");
        let handle = tokio::task::spawn_blocking(move || {
            let result = catch_unwind(AssertUnwindSafe(job));
            drop((permit, ticket));
            result
        });
        match handle.await {
            Ok(Ok(value)) => Ok(value),
            Ok(Err(panic)) => Err(PoolError::Panicked(panic_message(panic.as_ref()))),
            Err(e) => Err(PoolError::Panicked(e.to_string())),
        }
    }
}

/// The message of a panic payload.
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    /// A job that blocks until released, and tells when it has started.
    fn blocking_job(
        pool: &WorkerPool,
    ) -> (
        tokio::task::JoinHandle<Result<u32, PoolError>>,
        mpsc::Sender<()>,
        tokio::sync::oneshot::Receiver<()>,
    ) {
        let (release, wait) = mpsc::channel::<()>();
        let (started_tx, started) = tokio::sync::oneshot::channel();
        let pool = pool.clone();
        let handle = tokio::spawn(async move {
            pool.run(None, move || {
                let _ = started_tx.send(());
                wait.recv().unwrap();
                7
            })
            .await
        });
        (handle, release, started)
    }

    #[tokio::test]
    async fn refuses_beyond_workers_plus_queue() {
        let pool = WorkerPool::new(1, 1);
        let (first, release_first, started) = blocking_job(&pool);
        started.await.unwrap();
        assert_eq!(pool.busy(), 1);
        // The second waits in the queue...
        let queued = {
            let pool = pool.clone();
            tokio::spawn(async move { pool.run(None, || 8).await })
        };
        while pool.admitted() < 2 {
            tokio::task::yield_now().await;
        }
        // ...and a third is refused at once.
        assert_eq!(pool.run(None, || 9).await, Err(PoolError::QueueFull));
        release_first.send(()).unwrap();
        assert_eq!(first.await.unwrap(), Ok(7));
        assert_eq!(queued.await.unwrap(), Ok(8));
        assert_eq!(pool.admitted(), 0);
        assert_eq!(pool.run(None, || 10).await, Ok(10));
    }

    #[tokio::test]
    async fn gives_up_waiting_at_the_deadline() {
        let pool = WorkerPool::new(1, 4);
        let (first, release, started) = blocking_job(&pool);
        started.await.unwrap();
        let past = Instant::now();
        assert_eq!(pool.run(Some(past), || 1).await, Err(PoolError::TimedOut));
        release.send(()).unwrap();
        first.await.unwrap().unwrap();
        // With a free worker a passed deadline does not refuse the job.
        assert_eq!(pool.run(Some(past), || 2).await, Ok(2));
    }

    #[tokio::test]
    async fn a_panicking_job_is_an_error_and_frees_its_place() {
        let pool = WorkerPool::new(1, 0);
        let r = pool.run(None, || -> u32 { panic!("boom") }).await;
        assert_eq!(r, Err(PoolError::Panicked("boom".into())));
        assert_eq!(pool.admitted(), 0);
        assert_eq!(pool.run(None, || 3).await, Ok(3));
    }
}
